"""The flight's rerun recording: the recorder, its rows and batches, the blueprint, the 3-D scene,
the flight log."""

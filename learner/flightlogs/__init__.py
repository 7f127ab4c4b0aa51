"""Flight logs from any source, in one format: `FlightLog` (flightlog), tables through a
column mapping (tables), our rerun recordings (recording: the layout and its reader;
recording_log: a recording as a FlightLog), one entry point for every format registered
there (readers.read_log)."""

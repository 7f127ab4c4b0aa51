"""Online learning in flight: the learner's host, its process, the learning samples."""

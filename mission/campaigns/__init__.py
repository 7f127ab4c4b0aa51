"""Many flights with a purpose: the thesis experiments, benchmarks, the gap bench, online
evaluation and data gathering."""

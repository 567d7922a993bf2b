"""What the tests, the benchmarks and the studies share: message factories, fault trials, fuzzing."""

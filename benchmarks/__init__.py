"""Scripts that measure the service and write docs/benchmarks.md (run: make bench)."""

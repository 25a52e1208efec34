"""The thesis's RTT and start-up benchmarks."""

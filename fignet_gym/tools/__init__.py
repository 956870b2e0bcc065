"""Command-line tools that sit on top of everything else: the demo and the benchmarks."""

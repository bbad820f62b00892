"""Room: the tools (benchmarks). May import: anything in laneshift."""

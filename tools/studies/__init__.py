"""Room: the tools (studies). May import: anything in laneshift."""

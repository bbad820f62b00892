"""laneshift: the import root; the shared contract lives on this floor.

Room: the contract (shared by every process). May import: other contract modules only, never a
component, deploy or a tool."""

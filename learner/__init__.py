"""laneshift package."""

"""laneshift.replay_server: the replay tables and rules, served over zenoh and HTTP.

Room: replay_server (component). May import: the contract and laneshift.replay_server; never another
component."""

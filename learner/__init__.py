"""laneshift.learner: Double DQN, the learner loop, its metrics and links.

Room: learner (component). May import: the contract and laneshift.learner; never another component."""

"""laneshift.deploy: the one builder, the launchers and each component as a Ray actor.

Room: deploy, the wiring. May import: the contract, the components and the demo tools; never the
studies, the benchmarks or the CLI."""

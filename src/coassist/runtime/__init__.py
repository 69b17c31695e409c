"""The runtime: one control loop, several worlds (docs/architecture.md, *One loop, several worlds*)."""

"""The runtime: one control loop, several worlds (DESIGN §7)."""

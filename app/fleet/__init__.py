"""The fleet bridge: the plan sent to robots as VDA 5050 orders over MQTT, and their state
back as execution reports (docs/fleet.md)."""

"""A fleet over Eclipse Zenoh: edge servers publish their vehicles and answer commands,
a fleet server (``--fleet``) sees and flies them all (docs/fleet.md)."""

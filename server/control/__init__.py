"""The control core: the vehicles the server knows, who may fly them (leases, takeovers,
tokens, rate limits, lockout), what happens when an operator is lost (the deadman), the
audit log and control events, and each vehicle's one state publisher.

No HTTP, WebSocket, Zenoh or 3D scene here: ``server.api``, ``server.fleet`` and
``server.scene`` are adapters over it, and it flies vehicles only through ``server.link``."""

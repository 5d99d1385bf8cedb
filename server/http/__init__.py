"""What the server's HTTP surfaces (the vehicle API and the fleet's routes) share: how
failures become answers, the token checks as dependencies, the security middleware,
WebSocket admission, and the request and answer models."""

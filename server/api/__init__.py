"""The v1 HTTP and WebSocket API over the link layer's vehicles."""

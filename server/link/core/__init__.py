"""What every plugin shares: the vehicle core (who it is, whether it is heard, how to send to
it), the one request protocol, events, state subscriptions, liveness and the link's counters."""

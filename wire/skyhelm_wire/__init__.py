"""SkyHelm's wire format, defined once: what the HTTP API and its WebSocket carry, as
pydantic models (and the setpoint kinds as the frozen dataclasses the server's link flies).

The server's API takes its request and response models (and so its OpenAPI) from here, the
Python client (``skyhelm_client``) parses answers with them, and the page's typedefs
(``web/wire.d.js``) are generated from them (``python -m tools.gen_wire_js``). Nothing here
imports the server, pymavlink, FastAPI or numpy: pydantic is the one dependency.

Modules: ``setpoint_kinds`` (the kinds, with units and limits), ``setpoints`` (their request
bodies), ``state`` (a vehicle's state), ``commands`` (a command's result), ``control`` (the
lease), ``messages`` (the WebSockets' messages: states, events, control), ``sockets`` (the
WebSockets' paths and who may open them), ``signing``, ``common`` (errors, health, the
number types).
"""

"""``tpad-rt serve``: a renderer for apps in any language, over a local network API.

API map
-------
protocol
    the JSON messages: PROTOCOL_VERSION, the limits, ``parse(raw)`` / ``validate(data)``
    into typed requests, ProtocolError and its ``error`` reply
core
    the decisions apart from the network: ClockMap (client clock onto the stream's),
    FingerOwner (one finger, first come), TokenBucket (rate limits), TextureLibrary
    (names, paths within the allowed folders, inline YAML), TelemetryFeed, the page's images
server
    Settings, Server(renderer, settings): WebSocket at ``/ws``, the page at ``/``, OSC
osc
    OSC over UDP onto the same requests
static/
    the page (HTML, JS, CSS; no build step)

docs/serve.md is the protocol and the policies; ``tpad_rt.cli.serve`` the command.
"""

"""What everything above builds on: message codecs (modes, commands, setpoints, PX4's extra
messages, STATUSTEXT, signing, .tlog), the state snapshot's types, URLs and small helpers.
Nothing here imports a layer above."""

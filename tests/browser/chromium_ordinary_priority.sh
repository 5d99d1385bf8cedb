#!/bin/sh
# Debian's Chromium without the right to raise its own priority (CAP_SYS_NICE). Run as root,
# Chromium puts its display threads at nice -8; in the suite, where two browsers render WebGL
# in software beside other tests' servers and simulated vehicles, those threads took the
# cores from the vehicles and servers under test. tests/browser/harness.py starts it so, and
# brings back to nice 0 what Chromium lowers and can no longer raise (ordinary_priority.py).
exec setpriv --inh-caps=-sys_nice --bounding-set=-sys_nice /usr/bin/chromium "$@"

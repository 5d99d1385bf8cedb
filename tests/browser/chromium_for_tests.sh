#!/bin/sh
# Debian's Chromium as the tests start it (tests/browser/harness.py).
#
# Its feature switches merged: Chromium keeps only the last --disable-features (and the last
# --enable-features) of its command line, and Playwright puts its own list before the
# tests' arguments, so a list of the tests' own would silently drop Playwright's. Here every
# --disable-features value goes into one switch, and every --enable-features value into one.
#
# Run as root where setpriv is there, without the right to raise its own priority
# (CAP_SYS_NICE): as root Chromium puts its display threads at nice -8, and in the suite,
# where two browsers draw in software beside other tests' servers and simulated vehicles,
# those threads took the cores from the vehicles and servers under test. harness.py brings
# back to nice 0 what Chromium lowers and can no longer raise (ordinary_priority.py).
disabled=""
enabled=""
for arg do
  shift
  case "$arg" in
    --disable-features=*) disabled="${disabled:+$disabled,}${arg#--disable-features=}" ;;
    --enable-features=*) enabled="${enabled:+$enabled,}${arg#--enable-features=}" ;;
    *) set -- "$@" "$arg" ;;
  esac
done
if [ -n "$disabled" ]; then set -- "$@" "--disable-features=$disabled"; fi
if [ -n "$enabled" ]; then set -- "$@" "--enable-features=$enabled"; fi
if [ "$(id -u)" = 0 ] && command -v setpriv >/dev/null 2>&1; then
  exec setpriv --inh-caps=-sys_nice --bounding-set=-sys_nice /usr/bin/chromium "$@"
fi
exec /usr/bin/chromium "$@"

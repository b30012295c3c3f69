#!/usr/bin/env bash
# The browser tests (the explorer, the HTML reports) drive Debian's chromium. When it is missing and
# we are root, say what is installed and why, then install it with apt-get; otherwise say that those
# tests will be skipped (each says why). Always exits 0: nothing else in the suite needs a browser.
set -u
if command -v chromium >/dev/null 2>&1; then
    exit 0
fi
if [ "$(id -u)" != "0" ] || ! command -v apt-get >/dev/null 2>&1; then
    echo "ensure_chromium: the browser tests (explorer, HTML report) need chromium, which is missing;" \
        "installing it needs root and apt-get, so those tests will be skipped" >&2
    exit 0
fi
echo "ensure_chromium: the browser tests (explorer, HTML report) need chromium;" \
    "installing Debian's chromium with apt-get (apt-get update, then apt-get install chromium)" >&2
log=$(mktemp)
if { apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium; } >"$log" 2>&1; then
    echo "ensure_chromium: installed $(chromium --version 2>/dev/null || echo chromium)" >&2
else
    tail -n 5 "$log" >&2
    echo "ensure_chromium: apt-get install chromium failed; the browser tests will be skipped" >&2
fi
rm -f "$log"
exit 0

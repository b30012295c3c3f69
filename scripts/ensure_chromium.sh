#!/usr/bin/env bash
# Install Chromium (for the report's headless rendering test) when it is missing and we are root.
# Always exits 0: without Chromium that one test is skipped with its reason, nothing else changes.
set -u
for browser in chromium chromium-browser google-chrome; do
    if command -v "$browser" >/dev/null 2>&1; then
        exit 0
    fi
done
if [ "$(id -u)" != "0" ] || ! command -v apt-get >/dev/null 2>&1; then
    echo "ensure_chromium: chromium is missing and cannot be installed here (needs root and apt-get)" >&2
    exit 0
fi
echo "ensure_chromium: installing chromium with apt-get" >&2
if ! { apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium; } >/dev/null 2>&1; then
    echo "ensure_chromium: apt-get install chromium failed; the rendering test will be skipped" >&2
fi
exit 0

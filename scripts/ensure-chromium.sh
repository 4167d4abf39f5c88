#!/usr/bin/env bash
# The HTML-report test opens the page in headless Chromium (Debian's package). Installs it when it
# is missing and this user may (root with apt-get); otherwise says so, and that test is skipped.
set -u
command -v chromium >/dev/null 2>&1 && exit 0
if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
  echo "installing Debian's chromium for the HTML report test (apt-get)..."
  if apt-get update -qq >/dev/null && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null; then
    exit 0
  fi
fi
echo "note: chromium is not installed and could not be installed here; the test that renders the HTML report in a browser will be skipped (install it with: apt-get install chromium)" >&2
exit 0

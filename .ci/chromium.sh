#!/usr/bin/env bash
# Debian's Chromium for the web page's browser tests (tests/api/test_web_browser.py drives it with
# playwright-core; no browser is ever downloaded by the test tool). Used by `make test` and .ci/run alike,
# so both run the browser tests wherever Chromium can be installed, and say so where it cannot.
set -uo pipefail
if command -v chromium >/dev/null 2>&1; then
  exit 0
fi
if [[ $(id -u) == 0 ]] && command -v apt-get >/dev/null 2>&1; then
  echo "chromium: installing Debian's chromium for the browser tests (apt-get, about a minute) ..."
  if { apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends chromium >/dev/null; }; then
    exit 0
  fi
  echo "chromium: could not be installed; the browser tests (tests/api/test_web_browser.py) will SKIP"
else
  echo "chromium: not found and not root; the browser tests (tests/api/test_web_browser.py) will SKIP."
  echo "          install it to run them: sudo apt-get install -y chromium"
fi
exit 0

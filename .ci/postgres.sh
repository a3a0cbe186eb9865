#!/usr/bin/env bash
# Debian's PostgreSQL server binaries for `make test-scale` (tests/pg_server.py starts a throwaway server
# with them: initdb + pg_ctl in a temp dir, as the `postgres` account when run as root). Used by the
# Makefile and .ci/run alike; where it cannot be installed, says so, and the PostgreSQL cases SKIP.
set -uo pipefail
if compgen -G "/usr/lib/postgresql/*/bin/pg_ctl" >/dev/null || command -v pg_ctl >/dev/null 2>&1; then
  exit 0
fi
if [[ $(id -u) == 0 ]] && command -v apt-get >/dev/null 2>&1; then
  echo "postgresql: installing Debian's postgresql for the PostgreSQL suites (apt-get, about a minute) ..."
  if { apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends postgresql >/dev/null; }; then
    exit 0
  fi
  echo "postgresql: could not be installed; the PostgreSQL cases of make test-scale will SKIP"
else
  echo "postgresql: not found and not root; the PostgreSQL cases of make test-scale will SKIP."
  echo "            install it to run them: sudo apt-get install -y postgresql"
fi
exit 0

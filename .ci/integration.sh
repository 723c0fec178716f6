#!/usr/bin/env bash
# Integration tests against real services: an MLflow tracking server backed by PostgreSQL, and the
# MLflow UI in headless Chromium, started by the tests themselves on loopback. Installs what a
# fresh machine lacks.
set -euo pipefail
cd "$(dirname "$0")/.."

# PostgreSQL's server binaries (initdb, pg_ctl). Debian keeps them under /usr/lib/postgresql/*/bin.
if ! ls /usr/lib/postgresql/*/bin/initdb >/dev/null 2>&1 && ! command -v initdb >/dev/null 2>&1; then
    SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq postgresql >/dev/null
fi
# Running as root, the test drops to the `postgres` account, which the Debian package creates.
if [ "$(id -u)" -eq 0 ] && ! id postgres >/dev/null 2>&1; then
    useradd --system --no-create-home --shell /usr/sbin/nologin postgres
fi

# The MLflow UI test (tests/test_mlflow_ui.py) opens the UI in Debian's headless Chromium.
if ! command -v chromium >/dev/null 2>&1; then
    SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq chromium >/dev/null
fi

# The MLflow server talks to PostgreSQL through psycopg2 (the project's `postgres` extra).
if ! python -c "import psycopg2" 2>/dev/null; then
    python -m pip install -q "psycopg2-binary>=2.9"
fi

python -m pytest -m integration -p no:cacheprovider "$@"

#!/usr/bin/env bash
# Integration tests against real services: an MLflow tracking server backed by PostgreSQL, the MLflow
# UI in headless Chromium, a single-node SLURM cluster and a local Ray cluster, each started by the
# tests themselves on loopback and stopped after them. Installs what a fresh machine lacks (apt-get, pip).
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

# The MLflow UI test (tests/integration/test_mlflow_ui.py) opens the UI in Debian's headless Chromium.
if ! command -v chromium >/dev/null 2>&1; then
    SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq chromium >/dev/null
fi

# The MLflow server talks to PostgreSQL through psycopg2 (the project's `postgres` extra).
if ! python -c "import psycopg2" 2>/dev/null; then
    python -m pip install -q "psycopg2-binary>=2.9"
fi

# A single-node SLURM cluster (tests/integration/test_integration_clusters.py starts and stops its
# daemons): Debian's slurm-wlm, slurmdbd, munge and mariadb-server (slurmdbd keeps accounting for sacct).
bash .ci/slurm_cluster.sh install

# Ray: the `ray` extra, installed here only (it holds cloudpickle below 3 and so joblib below 1.6,
# which the default install does not need). Into the active environment: CI's own .ci-venv.
if ! python -c "import hydra_plugins.hydra_ray_launcher, ray" 2>/dev/null; then
    python -m pip install -q -e ".[ray]"
fi

start=$(date +%s)
python -m pytest -m integration -p no:cacheprovider "$@"
echo "integration tests: $(( $(date +%s) - start )) s"

#!/usr/bin/env bash
# A single-node SLURM cluster on this machine, for tests/integration/test_integration_clusters.py:
# munge (authentication), MariaDB + slurmdbd (accounting, so that `sacct` shows requeues),
# slurmctld and slurmd on 127.0.0.1, one partition `ci` holding this machine.
#
#   bash .ci/slurm_cluster.sh install        # apt-get: slurm-wlm, slurmdbd, munge, mariadb-server
#   bash .ci/slurm_cluster.sh start DIR      # every file and daemon of the cluster under DIR
#   bash .ci/slurm_cluster.sh stop DIR       # stops what `start DIR` started (DIR stays)
#
# `start` writes DIR/slurm.conf: point SLURM_CONF at it for sbatch, squeue, sacct and scontrol
# (submitit's requeue runs `scontrol requeue` inside the job, which inherits SLURM_CONF through
# sbatch). Ports are chosen free at start. Every daemon runs as root (SlurmUser=root), as CI does.
# Nothing is written outside DIR but munge's key and socket (/etc/munge, /run/munge), which the
# Debian package owns. Accounting (sacct) needs slurmdbd, and slurmdbd a MySQL/MariaDB database:
# Slurm 22.05 has no file-based accounting store.
set -euo pipefail

need_root() { [ "$(id -u)" -eq 0 ] || { echo "slurm_cluster.sh: run as root (slurmd must)"; exit 1; }; }

free_port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])'; }

wait_for() {  # wait_for SECONDS WHAT COMMAND...: retry COMMAND once a second
    local limit=$1 what=$2; shift 2
    for _ in $(seq "$limit"); do "$@" >/dev/null 2>&1 && return 0; sleep 1; done
    echo "slurm_cluster.sh: $what did not come up in ${limit}s"; return 1
}

install() {
    if command -v slurmctld >/dev/null && command -v slurmdbd >/dev/null && command -v munged >/dev/null \
        && command -v mariadbd >/dev/null; then
        return 0
    fi
    local sudo=""; [ "$(id -u)" -ne 0 ] && sudo="sudo"
    $sudo apt-get update -qq
    # The packages' own services are not started here (no init system in CI); `start` runs the daemons.
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq slurm-wlm slurmdbd munge mariadb-server >/dev/null
}

start() {
    need_root
    local dir; dir=$(realpath -m "$1")
    mkdir -p "$dir"/{state,spool,mysql}
    chmod 755 "$dir"  # the mysql account reads its data directory below it
    chown mysql:mysql "$dir/mysql"
    local host; host=$(hostname -s)
    local cpus; cpus=$(nproc)
    local mem; mem=$(awk '/MemTotal/ {print int($2 / 1024 * 0.8)}' /proc/meminfo)
    local ctld_port slurmd_port dbd_port db_port
    ctld_port=$(free_port); slurmd_port=$(free_port); dbd_port=$(free_port); db_port=$(free_port)

    # munge: the Debian package made /etc/munge/munge.key; make one if it did not.
    if [ ! -s /etc/munge/munge.key ]; then
        (command -v mungekey >/dev/null && mungekey --create --force) || \
            dd if=/dev/urandom of=/etc/munge/munge.key bs=1024 count=1 status=none
        chown munge:munge /etc/munge/munge.key; chmod 400 /etc/munge/munge.key
    fi
    mkdir -p /run/munge /var/log/munge /var/lib/munge
    chown munge:munge /run/munge /var/log/munge /var/lib/munge
    if ! munge -n </dev/null 2>/dev/null | unmunge >/dev/null 2>&1; then
        runuser -u munge -- munged
        touch "$dir/munged.ours"  # `stop` stops it
        wait_for 20 munged sh -c 'munge -n </dev/null | unmunge'
    fi

    # MariaDB for slurmdbd, on 127.0.0.1:<free port>, its files under DIR/mysql.
    mariadb-install-db --no-defaults --user=mysql --datadir="$dir/mysql" --skip-test-db \
        --auth-root-authentication-method=socket >"$dir/mariadb-install.log" 2>&1
    runuser -u mysql -- mariadbd --no-defaults --datadir="$dir/mysql" --socket="$dir/mysql/mysqld.sock" \
        --port="$db_port" --bind-address=127.0.0.1 --pid-file="$dir/mysql/mariadb.pid" \
        --log-error="$dir/mariadb.log" --innodb-buffer-pool-size=64M >/dev/null 2>&1 &
    wait_for 60 MariaDB mariadb --no-defaults -S "$dir/mysql/mysqld.sock" -u root -e 'SELECT 1'
    mariadb --no-defaults -S "$dir/mysql/mysqld.sock" -u root -e "
        CREATE USER 'slurm'@'127.0.0.1' IDENTIFIED BY 'slurm';
        GRANT ALL ON slurm_acct_db.* TO 'slurm'@'127.0.0.1';"

    cat >"$dir/slurmdbd.conf" <<EOF
AuthType=auth/munge
DbdAddr=127.0.0.1
DbdHost=localhost
DbdPort=$dbd_port
SlurmUser=root
LogFile=$dir/slurmdbd.log
PidFile=$dir/slurmdbd.pid
StorageType=accounting_storage/mysql
StorageHost=127.0.0.1
StoragePort=$db_port
StorageUser=slurm
StoragePass=slurm
StorageLoc=slurm_acct_db
EOF
    chmod 600 "$dir/slurmdbd.conf"

    # Short timers: a test cluster, where the defaults (minutes) would only add waiting.
    cat >"$dir/slurm.conf" <<EOF
ClusterName=hgmci
SlurmctldHost=$host(127.0.0.1)
SlurmctldPort=$ctld_port
SlurmdPort=$slurmd_port
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
# A requeued job waits cred_expire + 1 s before it may start again (default 120 s).
AuthInfo=cred_expire=10
StateSaveLocation=$dir/state
SlurmdSpoolDir=$dir/spool
SlurmctldPidFile=$dir/slurmctld.pid
SlurmdPidFile=$dir/slurmd.pid
SlurmctldLogFile=$dir/slurmctld.log
SlurmdLogFile=$dir/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/linux
JobAcctGatherFrequency=30
AccountingStorageType=accounting_storage/slurmdbd
AccountingStorageHost=localhost
AccountingStoragePort=$dbd_port
JobCompType=jobcomp/none
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
SchedulerType=sched/backfill
MpiDefault=none
ReturnToService=2
SlurmctldTimeout=30
SlurmdTimeout=30
InactiveLimit=0
MinJobAge=600
KillWait=10
Waittime=0
NodeName=$host NodeAddr=127.0.0.1 CPUs=$cpus RealMemory=$mem State=UNKNOWN
PartitionName=ci Nodes=$host Default=YES MaxTime=INFINITE State=UP
EOF
    export SLURM_CONF="$dir/slurm.conf"  # slurmdbd reads slurmdbd.conf from the same directory
    slurmdbd
    wait_for 60 slurmdbd sacctmgr -n list cluster
    sacctmgr -i add cluster hgmci >/dev/null
    slurmctld -f "$SLURM_CONF"
    slurmd -f "$SLURM_CONF"
    wait_for 60 "the node" sh -c "sinfo -h -N -o %t | grep -qx idle"
    echo "SLURM cluster up: SLURM_CONF=$SLURM_CONF"
    sinfo
}

stop() {
    local dir; dir=$(realpath -m "$1")
    export SLURM_CONF="$dir/slurm.conf"
    [ -f "$SLURM_CONF" ] && scancel --full --quiet --user="$(id -un)" 2>/dev/null || true
    for pidfile in slurmd.pid slurmctld.pid slurmdbd.pid mysql/mariadb.pid; do
        [ -f "$dir/$pidfile" ] || continue
        local pid; pid=$(cat "$dir/$pidfile")
        kill "$pid" 2>/dev/null || continue
        for _ in $(seq 30); do kill -0 "$pid" 2>/dev/null || break; sleep 1; done
        kill -9 "$pid" 2>/dev/null || true
    done
    # munged only if `start` started it (another user of munge on this machine keeps its own).
    if [ -f "$dir/munged.ours" ] && [ -f /run/munge/munged.pid ]; then
        kill "$(cat /run/munge/munged.pid)" 2>/dev/null || true
        rm -f "$dir/munged.ours"
    fi
}

case "${1:-}" in
    install) install ;;
    start) start "${2:?usage: slurm_cluster.sh start DIR}" ;;
    stop) stop "${2:?usage: slurm_cluster.sh stop DIR}" ;;
    *) echo "usage: slurm_cluster.sh install | start DIR | stop DIR"; exit 2 ;;
esac

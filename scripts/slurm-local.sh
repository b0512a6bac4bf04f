#!/usr/bin/env bash
# A single-node Slurm cluster on this machine, for the Slurm tests and local studies.
#
#   eval "$(scripts/slurm-local.sh start)"   # starts munged, slurmctld, slurmd; prints exports
#   scripts/slurm-local.sh stop
#
# Debian's slurm-wlm and munge are installed with apt-get where missing (as root). The
# configuration is scripts/slurm/slurm.conf.in with this machine's name, cores and memory; its
# state lives under target/slurm (or $DGSTEREO_SLURM_STATE). `start` is idempotent: with the
# daemons up and the node idle it only prints the exports. Every daemon runs as root.
set -euo pipefail
cd "$(dirname "$0")/.."
state="${DGSTEREO_SLURM_STATE:-$PWD/target/slurm}"
conf="$state/slurm.conf"

say() { echo "$@" >&2; }

install() {
    if command -v slurmctld > /dev/null && command -v slurmd > /dev/null && command -v munged > /dev/null; then
        return
    fi
    if [ "$(id -u)" != 0 ] || ! command -v apt-get > /dev/null; then
        say "error: Slurm is not installed (Debian: apt-get install slurm-wlm munge), and this is not root on Debian"
        exit 1
    fi
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends slurm-wlm munge > /dev/null
}

running() { [ -f "$1" ] && kill -0 "$(cat "$1")" 2> /dev/null; }

start() {
    install
    mkdir -p "$state/ctld" "$state/spool" "$state/munge"
    local host cpus memory
    host="$(hostname -s)"
    cpus="$(nproc)"
    memory="$(awk '/MemTotal/ {print int($2 / 1024 * 0.9)}' /proc/meminfo)"
    sed -e "s|@HOST@|$host|g" -e "s|@CPUS@|$cpus|g" -e "s|@MEMORY@|$memory|g" -e "s|@STATE@|$state|g" \
        -e "s|@CTLD_PORT@|${DGSTEREO_SLURMCTLD_PORT:-6817}|g" -e "s|@D_PORT@|${DGSTEREO_SLURMD_PORT:-6818}|g" \
        scripts/slurm/slurm.conf.in > "$conf.new"
    mv "$conf.new" "$conf"
    export SLURM_CONF="$conf"
    if ! running "$state/munge/munged.pid"; then
        [ -f /etc/munge/munge.key ] || { mungekey --create 2> /dev/null || /usr/sbin/create-munge-key -f > /dev/null; }
        munged --force --socket="$state/munge/munge.socket" --pid-file="$state/munge/munged.pid" \
            --log-file="$state/munge/munged.log" --seed-file="$state/munge/munged.seed"
    fi
    # Slurm finds munge's socket through the default path; point it there.
    mkdir -p /run/munge
    ln -sf "$state/munge/munge.socket" /run/munge/munge.socket.2
    running "$state/slurmctld.pid" || slurmctld -f "$conf"
    running "$state/slurmd.pid" || slurmd -f "$conf"
    for _ in $(seq 1 60); do
        if sinfo -h -o %T 2> /dev/null | grep -qE '^(idle|mixed|allocated)'; then
            echo "export SLURM_CONF=$conf"
            return
        fi
        scontrol update nodename="$host" state=resume > /dev/null 2>&1 || true
        sleep 0.5
    done
    say "error: the local Slurm node did not come up; logs in $state"
    exit 1
}

stop() {
    for pid in "$state/slurmd.pid" "$state/slurmctld.pid" "$state/munge/munged.pid"; do
        if running "$pid"; then
            kill "$(cat "$pid")"
        fi
    done
}

case "${1:-}" in
    start) start ;;
    stop) stop ;;
    *) say "usage: $0 start|stop"; exit 2 ;;
esac

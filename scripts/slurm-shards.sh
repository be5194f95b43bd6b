#!/usr/bin/env bash
# Sharded evaluation on a real Slurm: a one-node cluster from Debian's packages (slurmctld,
# slurmd and munge, installed with apt-get when missing), configured in a temporary directory
# and listening on 127.0.0.1 only (slurmctld binds the address its host name resolves to, which
# the script checks), runs `ferret eval --shard auto` as an array of 3 tasks
# (`sbatch --array=0-2 --wait`); `ferret merge` then joins them, and the merged trials.csv,
# summary.csv and paired.csv must be those of one machine, byte for byte. The daemons are
# stopped and the directory removed on exit.
#
#   sudo scripts/slurm-shards.sh                  # generated houses
#   FERRET_SLURM_EVAL="--houses …/multiroom-val150.jsonl.gz --trials-per-house all" \
#       scripts/slurm-shards.sh                   # any eval options
#
# Needs root (slurmd and munged are system daemons). FERRET_BIN is the ferret binary to run
# (default: this checkout's release build, which cargo brings up to date).
set -euo pipefail

ROOT="$(cd "$(dirname "$0")/.." && pwd)"
SHARDS=3
log() { printf '[slurm-shards %s] %s\n' "$(date +%H:%M:%S)" "$*" >&2; }

if [ "$(id -u)" -ne 0 ]; then
    log "needs root: slurmd and munged run as system daemons"
    exit 1
fi
if ! command -v slurmctld >/dev/null || ! command -v slurmd >/dev/null \
    || ! command -v sbatch >/dev/null || ! command -v munged >/dev/null; then
    log "installing slurm-wlm and munge"
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq slurm-wlm munge >/dev/null
fi
# shellcheck source=scripts/lib/ferret-bin.sh
source "$ROOT/scripts/lib/ferret-bin.sh"
ferret="$(ferret_bin)"
# shellcheck disable=SC2206 # the options are split on purpose
EVAL=(${FERRET_SLURM_EVAL:---generate 30 --trials-per-house all})

T="$(mktemp -d /tmp/ferret-slurm.XXXXXX)"
chmod 755 "$T"
stop() {
    for pid in "$T"/slurmd.pid "$T"/slurmctld.pid "$T"/munged.pid; do
        [ -s "$pid" ] && kill "$(cat "$pid")" 2>/dev/null || true
    done
    sleep 1
    rm -rf "$T"
}
trap stop EXIT

if ! getent hosts "$(hostname)" | grep -q '^127\.'; then
    log "$(hostname) does not resolve to a loopback address: slurmctld would listen beyond 127.0.0.1"
    exit 1
fi
# Ports of their own, so that the cluster does not meet a Slurm already on this machine.
free_port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'; }
CTLD_PORT="$(free_port)"
SLURMD_PORT="$(free_port)"
mkdir -p "$T/state" "$T/spool" "$T/out"
dd if=/dev/urandom of="$T/munge.key" bs=1024 count=1 status=none
chmod 400 "$T/munge.key"
munged --force --key-file="$T/munge.key" --socket="$T/munge.sock" --pid-file="$T/munged.pid" \
    --log-file="$T/munged.log" --seed-file="$T/munged.seed"
cpus="$(nproc)"
cat >"$T/slurm.conf" <<CONF
ClusterName=ferret
SlurmctldHost=localhost(127.0.0.1)
SlurmctldPort=$CTLD_PORT
SlurmdPort=$SLURMD_PORT
CommunicationParameters=NoInAddrAny,NoCtldInAddrAny
AuthType=auth/munge
AuthInfo=socket=$T/munge.sock
CredType=cred/munge
SlurmUser=root
SlurmdUser=root
StateSaveLocation=$T/state
SlurmdSpoolDir=$T/spool
SlurmctldPidFile=$T/slurmctld.pid
SlurmdPidFile=$T/slurmd.pid
SlurmctldLogFile=$T/slurmctld.log
SlurmdLogFile=$T/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
MpiDefault=none
ReturnToService=2
SchedulerType=sched/builtin
NodeName=localhost NodeAddr=127.0.0.1 CPUs=$cpus State=UNKNOWN
PartitionName=ferret Nodes=localhost Default=YES MaxTime=INFINITE State=UP
CONF
export SLURM_CONF="$T/slurm.conf"
slurmctld
slurmd -N localhost
for _ in $(seq 60); do
    sinfo -h -o %t 2>/dev/null | grep -qx idle && break
    sleep 1
done
if ! sinfo -h -o %t 2>/dev/null | grep -qx idle; then
    log "the node did not come up within a minute"
    tail -n 20 "$T/slurmctld.log" "$T/slurmd.log" >&2 || true
    exit 1
fi
log "cluster up ($cpus CPUs on 127.0.0.1:$CTLD_PORT); submitting --array=0-$((SHARDS - 1))"

OUT="$T/out"
# Each task runs on its own CPU; --shard auto reads SLURM_ARRAY_TASK_ID / _COUNT.
cat >"$T/shard.sbatch" <<JOB
#!/usr/bin/env bash
set -euo pipefail
"$ferret" eval ${EVAL[*]} --shard auto --out "$OUT/shard-\$SLURM_ARRAY_TASK_ID"
JOB
(cd "$T" && sbatch --wait --array=0-$((SHARDS - 1)) --cpus-per-task=1 \
    --output="$OUT/slurm-%A_%a.out" "$T/shard.sbatch" >/dev/null) || {
    log "the array failed:"
    tail -n 20 "$OUT"/slurm-*.out >&2 || true
    exit 1
}
log "array done; merging and running one machine"
"$ferret" merge "$OUT"/shard-* --out "$OUT/merged" >/dev/null
"$ferret" eval "${EVAL[@]}" --out "$OUT/one" >/dev/null
for f in trials.csv summary.csv paired.csv; do
    cmp "$OUT/one/$f" "$OUT/merged/$f"
done
log "3 Slurm array tasks + merge == one machine: trials.csv, summary.csv, paired.csv identical ($(($(wc -l <"$OUT/one/trials.csv") - 1)) trials)"

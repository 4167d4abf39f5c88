#!/usr/bin/env bash
# Prints the path of a Python >= 3.12: on PATH first, then under pyenv's versions.
# Exits 1 with instructions when there is none.
set -u
ok() { "$1" -c 'import sys; sys.exit(0 if sys.version_info >= (3, 12) else 1)' >/dev/null 2>&1; }
for name in python3.12 python3.13 python3.14 python3 python; do
  if path=$(command -v "$name" 2>/dev/null) && ok "$path"; then echo "$path"; exit 0; fi
done
for root in "${PYENV_ROOT:-}" "$HOME/.pyenv" /root/.pyenv; do
  [ -n "$root" ] && [ -d "$root/versions" ] || continue
  for path in $(ls -d "$root"/versions/3.*/bin/python3 2>/dev/null | sort -V); do
    if ok "$path"; then echo "$path"; exit 0; fi
  done
done
cat >&2 <<'MSG'
error: no Python >= 3.12 found (looked on PATH for python3.12..python3.14, python3 and under ~/.pyenv/versions).
The FE reference (dolfinx-solver-real) needs Python >= 3.12. Install one, then re-run, e.g.:
  pyenv install 3.12            # with pyenv
  sudo apt-get install python3.12 python3.12-venv   # Debian/Ubuntu with a recent release
or put a python3.12 on PATH, or run: make PYTHON=/path/to/python3.12 ...
MSG
exit 1

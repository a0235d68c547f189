#!/usr/bin/env bash
# Sets up dbench on a fresh Debian/Ubuntu machine: system LLVM for Mitsuba's llvm_ad_rgb variant,
# a Python 3.11 virtual environment in .venv, and every Python package (CPU build of torch).
# Idempotent: a second run only checks and returns.
set -euo pipefail
cd "$(dirname "$0")/.."
VENV=${DBENCH_VENV:-.venv}
PY=${PYTHON:-python3.11}

# 1. System packages. Mitsuba's llvm_ad_rgb aborts with libLLVM 15 ("Cannot select ... fminimum");
#    Dr.Jit finds libllvm19 by itself once it is installed.
if ! ldconfig -p 2>/dev/null | grep -q "libLLVM-19\|libLLVM.so.19"; then
  SUDO=""; [ "$(id -u)" -ne 0 ] && command -v sudo >/dev/null && SUDO="sudo"
  if [ "$(id -u)" -eq 0 ] || [ -n "$SUDO" ]; then
    echo "setup: installing libllvm19 (apt)"
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq libllvm19 >/dev/null
  else
    echo "setup: WARNING: cannot install libllvm19 (not root, no sudo); dbench will fall back" \
         "to Mitsuba's scalar_rgb variant and transient rendering will be unavailable" >&2
  fi
fi
# Headless Chromium and its driver for the HTML viewer's browser tests (Debian's packages; no
# browser is downloaded at run time).
if ! command -v chromium >/dev/null || ! command -v chromedriver >/dev/null; then
  SUDO=""; [ "$(id -u)" -ne 0 ] && command -v sudo >/dev/null && SUDO="sudo"
  if [ "$(id -u)" -eq 0 ] || [ -n "$SUDO" ]; then
    echo "setup: installing chromium and chromium-driver (apt)"
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq chromium chromium-driver >/dev/null
  else
    echo "setup: WARNING: cannot install chromium (not root, no sudo); the viewer's browser" \
         "tests will be skipped" >&2
  fi
fi
if ! command -v "$PY" >/dev/null; then
  if command -v apt-get >/dev/null && [ "$(id -u)" -eq 0 ]; then
    apt-get install -y -qq python3.11 python3.11-venv >/dev/null
  else
    echo "setup: $PY not found; install Python 3.11" >&2; exit 1
  fi
fi

# 2. Python environment. The stamp records the pyproject it was built from.
stamp="$VENV/.dbench-setup"
want=$(sha1sum pyproject.toml | cut -d' ' -f1)
if [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$want" ] && "$VENV/bin/python" -c "import dbench, mitsuba, torch" 2>/dev/null; then
  exit 0
fi
[ -x "$VENV/bin/python" ] || "$PY" -m venv "$VENV"
PIP=("$VENV/bin/pip" install -q --disable-pip-version-check)
"${PIP[@]}" --upgrade pip >/dev/null
# torch 2.13.0, CPU build: a local "+cpu" wheel (find-links) or PyTorch's CPU index wins over the
# several-GB CUDA wheel because its local version label sorts higher.
"${PIP[@]}" --retries 1 --timeout 30 --extra-index-url https://download.pytorch.org/whl/cpu \
  "torch==2.13.0" 2>&1 | grep -v "^WARNING" || true
"$VENV/bin/python" -c "import torch" 2>/dev/null || "${PIP[@]}" "torch==2.13.0"
# Triton: the version the GPU machines carry (3.6.0, with torch 2.11) and whose interpreter the
# kernel tests run on these CPU machines; pyproject allows any 3.x for GPU installs of torch.
"${PIP[@]}" -e ".[test]" "triton==3.6.0" 2>&1 | grep -v "^WARNING" || true
# ColorVideoVDP (the sequences' cvvdp column) without its declared dependencies: they would
# replace torch 2.13.0+cpu (any torchvision after 0.16 is a CUDA build for another torch, and
# 0.17-0.28 do not even import without their compiled operators, which need CUDA's libtorch).
# torchvision 0.16.2 imports on this torch without its compiled parts, and the metric uses only
# its Gaussian blur, written in PyTorch. The rest of what cvvdp imports is in pyproject.toml.
"${PIP[@]}" --no-deps "cvvdp==0.5.7" "torchvision==0.16.2" 2>&1 | grep -v "^WARNING" || true
"$VENV/bin/python" -W ignore -c "import importlib.util as u, dbench, mitsuba, torch, pyoidn, flip_evaluator, numba, OpenEXR, kornia, onnxruntime, skimage, pandas, matplotlib, selenium, triton, pycvvdp, xxhash; assert u.find_spec('mitransient'); assert torch.__version__.startswith('2.13.0')" \
  || { echo "setup: package installation failed" >&2; exit 1; }
echo "$want" > "$stamp"
echo "setup: done ($("$VENV/bin/python" -c 'import torch, mitsuba; print("torch", torch.__version__, "| mitsuba", mitsuba.__version__)'))"

#!/usr/bin/env bash
# Idempotent machine + venv set-up for soilvolume (Debian 12 bookworm, Python 3.11).
# Installs Debian packages (QGIS 3.40 LTR from bookworm-backports, Chromium for report tests),
# creates .venv with --system-site-packages on Debian's /usr/bin/python3 and installs the wheels.
set -euo pipefail
cd "$(dirname "$0")/.."
SUDO=""; [ "$(id -u)" -eq 0 ] || SUDO="sudo"
export DEBIAN_FRONTEND=noninteractive

need_apt=0
for pkg in python3-venv libusb-1.0-0 libgl1 libegl1 libgomp1 python3-qgis qgis-providers qgis chromium xvfb; do
  dpkg -s "$pkg" >/dev/null 2>&1 || need_apt=1
done
if [ "$need_apt" = 1 ]; then
  if [ ! -f /etc/apt/sources.list.d/backports.sources ]; then
    printf 'Types: deb\nURIs: http://deb.debian.org/debian\nSuites: bookworm-backports\nComponents: main\nSigned-By: /usr/share/keyrings/debian-archive-keyring.gpg\n' \
      | $SUDO tee /etc/apt/sources.list.d/backports.sources >/dev/null
  fi
  $SUDO apt-get update -qq
  $SUDO apt-get install -y -qq --no-install-recommends --no-upgrade \
    python3-venv libusb-1.0-0 libgl1 libegl1 libgomp1 chromium fonts-dejavu-core xvfb >/dev/null
  $SUDO apt-get install -y -qq --no-install-recommends -t bookworm-backports \
    python3-qgis qgis-providers qgis >/dev/null
fi

# bench-only (make bench runs CloudCompare's CLI beside the engine); the bench skips it when absent
if ! dpkg -s cloudcompare >/dev/null 2>&1; then
  $SUDO apt-get install -y -qq --no-install-recommends cloudcompare >/dev/null 2>&1 \
    || echo "setup: cloudcompare not installed (only make bench uses it; it skips CloudCompare without it)"
fi

if [ ! -x .venv/bin/python ]; then
  /usr/bin/python3 -m venv --system-site-packages .venv
fi
stamp=.venv/.deps-stamp
want=$(cat pyproject.toml constraints.txt plugin/engine-lock.txt scripts/setup.sh | sha256sum | cut -d' ' -f1)
if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$want" ]; then
  # the engine's pins (plugin/engine-lock.txt) as constraints: the tests test what users get
  grep -v '^open3d==' plugin/engine-lock.txt | sed 's/^numpy==.*/numpy<2/' > .venv/engine-constraints.txt
  .venv/bin/pip install -q --disable-pip-version-check -c constraints.txt -c .venv/engine-constraints.txt -e '.[dev]'
  echo "$want" > "$stamp"
fi
# the engine's native kernels (soilvolume/native/*.c) for the dev venv and the tests; the
# plugin's installer below finds them present (the same source, the same folder)
.venv/bin/python -m soilvolume.native.build
# the engine's modules byte-compiled now: each run is a new process, and where Python may not write
# them itself (PYTHONDONTWRITEBYTECODE, as on this project's runners) it would compile ~150 modules
# at every start (paper pair: 0.943 -> 0.885 s)
.venv/bin/python -m compileall -q soilvolume
# the engine's own environment, built by the plugin's installer (as QGIS users get it); the QGIS
# tests point the plugin to it (SOILVOLUME_ENGINE_ENV); quick when it is up to date
/usr/bin/python3 plugin/environment.py install .engine-env | grep -v '^WARNING: Location' | tail -3
.venv/bin/python -c "import soilvolume, open3d, rasterio, pyproj, laspy, CSF, qgis.core" \
  && echo "setup: OK ($(.venv/bin/python -c 'from qgis.core import Qgis; print("QGIS", Qgis.version())'))"

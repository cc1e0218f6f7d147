#!/usr/bin/env bash
# Build dist/soilvolume_qgis-<version>.zip, the file a user gives to QGIS's
# "Plugins > Manage and Install Plugins > Install from ZIP" (and to plugins.qgis.org).
# The zip holds one folder, soilvolume_qgis/, with the plugin and the engine package it needs:
#   metadata.txt __init__.py qgisplugin.py LICENSE plugin/ processing/ resources/ soilvolume/
# No tests, no venv, no caches. Output folder: $DIST_DIR (default dist/).
set -euo pipefail
cd "$(dirname "$0")/.."
name=soilvolume_qgis
dist=${DIST_DIR:-dist}

version=$(sed -n 's/^version=//p' metadata.txt | head -1 | tr -d '[:space:]')
engine_version=$(sed -n 's/^__version__ = "\(.*\)"/\1/p' soilvolume/__init__.py)
if [ -z "$version" ]; then echo "package: no version= in metadata.txt" >&2; exit 1; fi
if [ "$version" != "$engine_version" ]; then
  echo "package: metadata.txt version $version differs from soilvolume.__version__ $engine_version" >&2
  exit 1
fi

stage=$(mktemp -d)
trap 'rm -rf "$stage"' EXIT
mkdir "$stage/$name"
cp metadata.txt __init__.py qgisplugin.py "$stage/$name/"
for dir in plugin processing resources soilvolume; do
  cp -R "$dir" "$stage/$name/$dir"
done
if [ -f LICENSE ]; then
  cp LICENSE "$stage/$name/LICENSE"
elif [ -f /usr/share/common-licenses/GPL-2 ]; then
  # plugins.qgis.org rejects a zip without LICENSE; pyproject.toml says GPL-2.0-or-later
  echo "package: warning: no LICENSE in the repository, using the GPL-2 text" >&2
  cp /usr/share/common-licenses/GPL-2 "$stage/$name/LICENSE"
else
  echo "package: warning: no LICENSE file; plugins.qgis.org will reject the zip" >&2
fi
find "$stage" \( -name __pycache__ -o -name '*.egg-info' -o -name .pytest_cache \
  -o -name .ruff_cache \) -prune -exec rm -rf {} +
find "$stage" \( -name '*.pyc' -o -name '*.pyo' -o -name '.DS_Store' -o -name '*.partial.*' \
  -o -name '_soilvolume_kernels-*' -o -name '._soilvolume_kernels-*' \) -delete  # no binaries: the installer builds them

mkdir -p "$dist"
zipfile="$(cd "$dist" && pwd)/$name-$version.zip"
rm -f "$zipfile"
# reproducible: sorted entries, timestamps of the last commit (or now outside git)
epoch=${SOURCE_DATE_EPOCH:-$(git log -1 --format=%ct 2>/dev/null || date +%s)}
find "$stage" -exec touch -h -d "@$epoch" {} +
(cd "$stage" && find "$name" -print | LC_ALL=C sort | zip -q -X -D "$zipfile" -@)
echo "$zipfile"

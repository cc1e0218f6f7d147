#!/usr/bin/env bash
# Link the working tree into the local QGIS profile as the plugin "soilvolume_qgis", so QGIS runs
# the code being edited (restart QGIS or use the Plugin Reloader after changes).
#   scripts/deploy.sh            link (profile: $QGIS_PROFILE, default "default")
#   scripts/deploy.sh --remove   remove the link
# $QGIS_PLUGINS_DIR overrides the plugins folder.
set -euo pipefail
repo=$(cd "$(dirname "$0")/.." && pwd)
name=soilvolume_qgis
profile=${QGIS_PROFILE:-default}
case "$(uname -s)" in
  Darwin) base="$HOME/Library/Application Support/QGIS/QGIS3" ;;
  MINGW*|MSYS*|CYGWIN*) base="${APPDATA:-$HOME/AppData/Roaming}/QGIS/QGIS3" ;;
  *) base="${XDG_DATA_HOME:-$HOME/.local/share}/QGIS/QGIS3" ;;
esac
plugins=${QGIS_PLUGINS_DIR:-$base/profiles/$profile/python/plugins}
target="$plugins/$name"

if [ "${1:-}" = "--remove" ]; then
  if [ -L "$target" ]; then rm "$target"; echo "deploy: removed $target"; fi
  exit 0
fi
mkdir -p "$plugins"
if [ -e "$target" ] && [ ! -L "$target" ]; then
  echo "deploy: $target exists and is not a link (an installed zip?); remove it first" >&2
  exit 1
fi
ln -sfn "$repo" "$target"
echo "deploy: $target -> $repo"
echo "deploy: enable \"Soil Volume Change\" in Plugins > Manage and Install Plugins" \
     "(headless: qgis_process plugins enable $name)"

#!/bin/sh
# Regenerates the shipped default media, resources/media/vinyl-300 (docs/media.md "The
# default media"), by the closed loop on the default emulated printer: wedge, ink-limit
# chart, ArgyllCMS targen + colprof. Needs Debian's argyll. About a minute.
set -e
cd "$(dirname "$0")/.."
PY=${PYTHON:-.venv/bin/python}
"$PY" -m wideprint.app.cli media create vinyl-300 --dir resources/media --no-linearise --replace \
    --description "White solvent vinyl (the emulator's solvent-vinyl), 300 dpi 1 pass vced: the shipped default, made by media create on the default emulated printer"

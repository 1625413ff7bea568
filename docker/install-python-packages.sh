#!/bin/sh
# Inside the image build: install the project's dependencies for the given extras, pinned by
# constraints.txt, from a folder of wheels if it holds any (no network), else from the package index.
# usage: sh docker/install-python-packages.sh EXTRAS WHEEL_DIR      (run in /app, next to pyproject.toml)
set -eu
extras=$1
wheels=$2

if ls "$wheels"/*.whl >/dev/null 2>&1; then
    echo "installing Python packages for [$extras] from $(ls "$wheels"/*.whl | wc -l) local wheels (no index)"
    set -- --no-index --find-links "$wheels"
else
    echo "no wheels in docker/wheels/: installing Python packages for [$extras] from the package index"
    set --
fi
python docker/project-requirements.py pyproject.toml --extras "$extras" >/tmp/requirements.txt
pip install -q "$@" -c constraints.txt -r /tmp/requirements.txt "setuptools>=68" wheel
# mediapipe's metadata pins numpy<2 and opencv-contrib; its Hands API runs with what is installed (see setup.sh)
pip install -q "$@" -c constraints.txt --no-deps mediapipe
rm -f /tmp/requirements.txt
pip check || echo "(pip check: mediapipe's own pins are knowingly unmet, see scripts/setup.sh)"

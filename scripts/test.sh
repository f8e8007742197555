#!/usr/bin/env bash
# Set up everything the test suite needs on a fresh machine with Python 3.11 and pip, then run it.
set -euo pipefail
cd "$(dirname "$0")/.."

# VTK, the reference renderer of the tests, renders offscreen through EGL on Mesa's software
# rasterizer; these Debian packages provide it. Installed only when missing and possible.
if command -v apt-get >/dev/null 2>&1 && [ "$(id -u)" = "0" ]; then
  if ! dpkg -s libegl1 libegl-mesa0 libgl1-mesa-dri >/dev/null 2>&1; then
    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq \
      libegl1 libegl-mesa0 libgl1-mesa-dri >/dev/null
  fi
fi

# The browser tests drive Debian's Chromium through Playwright (a browser is never downloaded:
# `playwright install` is not used). Installed only when missing and possible; without it the
# browser tests are skipped and say so.
if command -v apt-get >/dev/null 2>&1 && [ "$(id -u)" = "0" ]; then
  if ! command -v chromium >/dev/null 2>&1; then
    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null
  fi
fi

python -m pip install -q --disable-pip-version-check -e ".[test]"
# The type checker first ([tool.mypy] in pyproject.toml: strict for session/, render/, tf/ and
# explorer/); a type error fails the run as a failing test does.
python -m mypy
python -m pytest "$@"

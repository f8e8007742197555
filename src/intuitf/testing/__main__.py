"""``python -m intuitf.testing fake-mllm [options]``: run a testing tool (the fake model server)."""

from __future__ import annotations

import sys

from intuitf.testing import fake_mllm

TOOLS = {"fake-mllm": fake_mllm.main}


def main(argv: list[str] | None = None) -> None:
    args = sys.argv[1:] if argv is None else argv
    if not args or args[0] not in TOOLS:
        print(f"usage: python -m intuitf.testing {{{','.join(TOOLS)}}} [options]", file=sys.stderr)
        sys.exit(2)
    TOOLS[args[0]](args[1:])


if __name__ == "__main__":
    main()

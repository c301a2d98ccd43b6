"""``python -m vintix.train`` (and ``torchrun --nproc-per-node N -m vintix.train``): same options as ``vintix train``."""

from __future__ import annotations

import argparse
import sys

from vintix.errors import VintixError
from vintix.train.config import load_config
from vintix.train.trainer import train


def main(argv: list[str] | None = None) -> int:
    """Parse the command line, train, return the exit status."""
    parser = argparse.ArgumentParser(prog="python -m vintix.train", description=__doc__)
    parser.add_argument("--config", default="tiny", help="model preset (tiny, small, paper) or a YAML of TrainConfig fields")
    parser.add_argument("--data", help="dataset root (overrides the config)")
    parser.add_argument("--out", help="run directory (overrides the config); re-running resumes")
    parser.add_argument("--set", dest="settings", action="append", default=[], metavar="FIELD=VALUE",
                        help="override one TrainConfig field (repeatable), e.g. --set max_steps=500")
    args = parser.parse_args(argv)
    from vintix.evaluate import in_context_scorer  # the entry point wires the stage above training in

    try:
        config = load_config(args.config, {"data": args.data, "out": args.out}, args.settings)
        train(config, scorer=in_context_scorer(config))
    except (VintixError, OSError) as error:  # like `vintix train`: a named error, not a traceback
        print(f"error: {error}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())

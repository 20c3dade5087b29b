"""``python -m bench sampler [--quick] [--device D]``."""

from __future__ import annotations

import argparse

from . import sampler

PARTS = {"sampler": sampler.run}


def main():
    p = argparse.ArgumentParser(prog="python -m bench", description="clcsg benchmarks (write JSON to bench/results/)")
    p.add_argument("part", choices=sorted(PARTS))
    p.add_argument("--quick", action="store_true", help="keep the part under a minute")
    p.add_argument("--device", default=None, help="cpu, gpu or P:D (default as for clcsg)")
    a = p.parse_args()
    PARTS[a.part](quick=a.quick, device=a.device)


if __name__ == "__main__":
    main()

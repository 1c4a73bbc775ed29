"""One fit against the same fit as map and merge on local Ray (issue #14).

    python3 crates/murk-py/bench/bench_fit_ray.py CAMPAIGN [--shards 8] [--cpus 2]

CAMPAIGN is any campaign folder, for example one written by
``target/debug/examples/map_merge_bench DIR 1000`` (``DIR/campaign-1000``).
Prints the one fit's time (``murk.fit``, every CPU), the Ray fit's time
(``murk.ray.fit`` on ``ray.init(num_cpus=CPUS)``, Ray start-up excluded) and
the overhead, and checks that the tables are byte-identical. Figures, not a
test.
"""

from __future__ import annotations

import argparse
import time

import murk


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("campaign")
    ap.add_argument("--shards", type=int, default=8)
    ap.add_argument("--cpus", type=int, default=2)
    args = ap.parse_args()

    import ray
    import murk.ray

    t = time.perf_counter()
    one = murk.fit(args.campaign, threads=args.cpus).to_json()
    t_one = time.perf_counter() - t
    print(f"one fit (murk.fit, {args.cpus} threads): {t_one:.2f} s")

    ray.init(num_cpus=args.cpus, include_dashboard=False, log_to_driver=False)
    # Warm the workers (process start and import of murk), as a long-lived
    # cluster would be.
    ray.get([ray.remote(lambda: __import__("murk").__version__).remote() for _ in range(args.cpus)])
    t = time.perf_counter()
    table = murk.ray.fit(args.campaign, shards=args.shards).to_json()
    t_ray = time.perf_counter() - t
    ray.shutdown()
    print(f"murk.ray.fit, {args.shards} shards on {args.cpus} CPUs: {t_ray:.2f} s "
          f"({100 * (t_ray / t_one - 1):+.1f} % against one fit)")
    assert table == one, "the Ray table differs from the one fit's"
    print("byte-identical tables")


if __name__ == "__main__":
    main()

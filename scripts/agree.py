#!/usr/bin/env python3
"""The two checkers must agree: compares `mres validate --json` with `check_mres.py --json`
on one file (levels; clusters, groups and triangles per level; root groups and clusters;
level-0 fill; both find no cracked cut and no violation, the open-edge marks of level 0 and of
every group included: docs/FORMAT.md §6) and prints one line. Exit 1 on any disagreement.

    scripts/agree.py RUST.json PYTHON.json NAME
"""
import json
import sys


def main():
    rust_path, python_path, name = sys.argv[1:4]
    rust = json.load(open(rust_path))
    py = json.load(open(python_path))
    py = py[0] if isinstance(py, list) else py
    problems = []

    def same(what, a, b):
        if a != b:
            problems.append(f"{what}: validate {a} vs checker {b}")

    same("levels", rust["levels"], py["levels"])
    per_level = lambda levels: [(l["level"], l["clusters"], l["groups"], l["triangles"]) for l in levels]
    same("per level (level, clusters, groups, triangles)", per_level(rust["per_level"]), per_level(py["per_level"]))
    same("root groups", rust["root_groups"], py["root_groups"])
    same("root clusters", rust["root_clusters"], py["root_clusters"])
    if abs(rust["level0_fill"] - py["level0_fill"]) > 1e-6:
        problems.append(f"level-0 fill: validate {rust['level0_fill']} vs checker {py['level0_fill']}")
    if rust["cracked_cuts"] != 0 or py["uniform_cracked"] != 0 or py["random_cracked"] != 0:
        problems.append(
            f"cracked cuts: validate {rust['cracked_cuts']}, checker {py['uniform_cracked']} uniform + "
            f"{py['random_cracked']} random"
        )
    if rust["violation_count"] != 0 or not py["ok"]:
        problems.append(f"violations: validate {rust['violation_count']}, checker ok={py['ok']}")
        problems += [f"validate: {v}" for v in rust["violations"]]
        problems += [f"checker: {v}" for v in py.get("violations", [])]
    c = rust["conditioning"]
    summary = (
        f"{name}: levels {rust['levels']}, roots {rust['root_groups']} group / {rust['root_clusters']} clusters, "
        f"fill {rust['level0_fill']:.1f}, edge age mean {c['edge_age_mean']:.2f}, "
        f"honesty worst {rust['honesty']['worst_ratio']:.2f}"
    )
    if problems:
        print(f"DISAGREE {summary}")
        for p in problems:
            print(f"  {name}: {p}")
        return 1
    print(f"agree {summary}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

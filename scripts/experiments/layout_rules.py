"""How well generated houses meet their style's layout rules, and how room adjacency differs
with and without them: for each house style with a [layout] table, N houses of it and N of the
same style without its rules (the generator's worlds of before the rules: for the apartment,
apartment_shuffled's), a table of the share meeting every rule, each rule's share, the share of
plans whose rooms all fit their styles, and P(a room of kind A shares a door with one of kind B)
for the pairs the rules name.

    python -m ctxsearch.scripts.experiments.layout_rules [--houses 200] [--styles apartment,...]
"""

from __future__ import annotations

import argparse
import dataclasses

import numpy as np

from ctxsearch.envs.floorplan import house_hash
from ctxsearch.envs.house_rules import violations
from ctxsearch.envs.houses import load_house
from ctxsearch.envs.plans import _misfit, plan


def _pairs(rules) -> list[tuple[str, str]]:
    out = [(k, t) for k, ts in rules.next_to for t in ts]
    out += [(k, t) for k, ts in rules.only_to for t in ts]
    return list(dict.fromkeys(out))


def measure(style, rules, n: int) -> dict:
    """Shares over seeds 0..n-1 of ``style``'s plans (the plan is a house's first draw, so it is
    the generated house's plan) judged by ``rules``."""
    every, fit = 0, 0
    entrance = [0, 0]  # (houses with the by_entrance kind, where it has the first door)
    per: dict[str, int] = {}
    pairs = {p: [0, 0] for p in _pairs(rules)}  # (houses with both kinds, with a door between)
    for seed in range(n):
        rng = np.random.default_rng([seed, house_hash(style.seed_name or style.name)])
        cells, passages, _, _ = plan(style, rng)
        kinds = [c.style.name if c.style else "corridor" for c in cells]
        doors = [(a, b, (x, y)) for a, b, x, y, _, _ in passages]
        broken = violations(rules, kinds, doors)
        every += not broken
        fit += _misfit(cells) == 0.0
        if rules.by_entrance in kinds:
            entrance[0] += 1
            entrance[1] += not any(v.startswith(f"{rules.by_entrance}.") for v in broken)
        for rule in {v.split(":")[0] for v in broken}:
            per[rule] = per.get(rule, 0) + 1
        links = {(kinds[a], kinds[b]) for a, b, _ in doors if b >= 0}
        links |= {(b, a) for a, b in links}
        for (a, b), c in pairs.items():
            if a in kinds and b in kinds and (a != b or kinds.count(a) > 1):
                c[0] += 1
                c[1] += (a, b) in links
    return {"every": every / n, "fit": fit / n, "broken": per, "pairs": pairs, "entrance": entrance}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--houses", type=int, default=200)
    ap.add_argument("--styles", default="apartment,family_house")
    args = ap.parse_args(argv)
    for name in args.styles.split(","):
        ruled = load_house(name)
        rules = ruled.layout_rules
        if rules is None:
            print(f"{name}: no [layout] rules")
            continue
        control = dataclasses.replace(ruled, layout_rules=None)
        rules_text = ", ".join(
            [f"{k}.next_to={list(v)}" for k, v in rules.next_to]
            + [f"{k}.only_to={list(v)}" for k, v in rules.only_to]
            + ([f"{rules.by_entrance}.by_entrance"] if rules.by_entrance else [])
        )
        print(f"\n{name} ({args.houses} houses each): {rules_text}")
        rows = [(name, measure(ruled, rules, args.houses)),
                (f"{name} without rules", measure(control, rules, args.houses))]  # fmt: skip
        names = [r for r, _ in rows]
        keys = sorted({k for _, m in rows for k in m["broken"]} | {
            f"{k}.next_to" for k, _ in rules.next_to} | {f"{k}.only_to" for k, _ in rules.only_to
        } | ({f"{rules.by_entrance}.by_entrance"} if rules.by_entrance else set()))  # fmt: skip
        w = max(len(x) for x in names) + 2
        print(f"{'':38s}" + "".join(f"{x:>{w}s}" for x in names))
        print(f"{'meets every rule':38s}" + "".join(f"{m['every']:>{w}.3f}" for _, m in rows))
        for k in keys:
            vals = "".join(f"{1 - m['broken'].get(k, 0) / args.houses:>{w}.3f}" for _, m in rows)
            print(f"{'  meets ' + k:38s}" + vals)
        print(
            f"{'every room fits its style':38s}" + "".join(f"{m['fit']:>{w}.3f}" for _, m in rows)
        )
        for a, b in _pairs(rules):
            label = f"P({a} shares a door with {b})"
            vals = "".join(
                f"{m['pairs'][(a, b)][1] / max(m['pairs'][(a, b)][0], 1):>{w - 6}.3f} (n={m['pairs'][(a, b)][0]:3d})"
                for _, m in rows
            )
            print(f"{label:38s}" + vals)
        if rules.by_entrance:
            label = f"P({rules.by_entrance} has the first door)"
            vals = "".join(
                f"{m['entrance'][1] / max(m['entrance'][0], 1):>{w - 6}.3f} (n={m['entrance'][0]:3d})"
                for _, m in rows
            )
            print(f"{label:38s}" + vals)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

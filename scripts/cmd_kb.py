"""``ctxsearch kb show|stats|merge`` (the evidence store) and ``ctxsearch bench kb``."""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sqlite3
import sys
import textwrap
from dataclasses import dataclass
from pathlib import Path

from ctxsearch.knowledge.catalog import load_catalog
from ctxsearch.knowledge.drift import ForgetKnowledgeBase, evidence_of
from ctxsearch.knowledge.errors import CatalogError, CtxsearchError, StoreError
from ctxsearch.knowledge.options import Forget, IntervalMethod, Rank
from ctxsearch.knowledge.persistence import STILL, LearnedPersistence, listing, store_checks
from ctxsearch.knowledge.pooling import PooledCounts, interval_rows
from ctxsearch.knowledge.room_context import RoomContext, next_relation_name, relation_name
from ctxsearch.knowledge.store import EvidenceStore, merge_stores
from ctxsearch.scripts import argtypes

SHOW_EXAMPLES = """\
examples:
  ctxsearch kb show demo/kb.sqlite                  intervals with y > 0, best lower bound first
  ctxsearch kb show demo/kb.sqlite --type Desk      only the relations of Desk (ON-TOP-OF-DESK, ...)
  ctxsearch kb show demo/kb.sqlite --related Cup    where Cups were found, relative to what
  ctxsearch kb show demo/kb.sqlite --type WorkSurface   a class: evidence pooled over its types
  ctxsearch kb show demo/kb.sqlite --related Container  any Cup, Bottle or Beaker
  ctxsearch kb show demo/kb.sqlite --type Table --backoff   a rare type backed off to its class
  ctxsearch kb show demo/kb.sqlite --all --alpha 0.05
  ctxsearch kb show demo/kb.sqlite --json > intervals.json
"""

MERGE_EXAMPLES = """\
examples:
  ctxsearch kb merge all.sqlite robot1.sqlite robot2.sqlite
  ctxsearch kb merge all.sqlite more.sqlite         appends to an existing all.sqlite
"""

BENCH_EXAMPLES = """\
examples:
  ctxsearch bench kb                                all sizes, prints the table only
  ctxsearch bench kb --sizes 100,1000 --out /tmp/bench
"""


def _emit(text: str) -> None:
    """Print ``text``; a closed pipe (``| head``) ends the output quietly."""
    try:
        sys.stdout.write(text if text.endswith("\n") else text + "\n")
        sys.stdout.flush()
    except BrokenPipeError:
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())


def _wrap(text: str) -> str:
    """A description paragraph wrapped for RawDescriptionHelpFormatter (which keeps newlines)."""
    return textwrap.fill(" ".join(text.split()), width=88)


def _sizes(text: str) -> tuple[int, ...]:
    try:
        sizes = tuple(int(s.replace("_", "")) for s in text.split(",") if s.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected comma-separated type counts, e.g. 100,1000, got {text!r}"
        ) from None
    if not sizes or min(sizes) < 2:
        raise argparse.ArgumentTypeError(f"expected type counts >= 2, got {text!r}")
    return sizes


def _add_catalog_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--catalog",
        type=Path,
        default=None,
        metavar="FILE",
        help="object-type catalog the store was built with (default: assets/types.toml)",
    )


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``kb show``, ``kb stats`` and ``kb merge``."""
    kb = sub.add_parser(
        "kb",
        help="inspect or merge knowledge stores (the learned confidence intervals)",
        description="A knowledge store is the SQLite evidence log written by `ctxsearch learn`: "
        "one row per examination and per observed (relation, type) pair. Counts and intervals "
        "are rebuilt from it, for any alpha.",
    )
    kb_sub = kb.add_subparsers(dest="kb_command", metavar="ACTION", required=True)

    _register_show(kb_sub)
    _register_stats(kb_sub)
    _register_merge(kb_sub)
    _register_maps(kb_sub)


def _register_show(kb_sub: argparse._SubParsersAction) -> None:
    """Add ``kb show``."""
    show = kb_sub.add_parser(
        "show",
        help="print the intervals INT(rel, B) of a store, sorted by lower bound",
        description=_wrap(
            "Print the confidence interval of P(rel(B)) for every relation rel and type "
            "B: y (examinations of rel's reference type with at least one B in rel) out of n "
            "(examinations of that type), and the Wilson interval [low, high] (paper eq. 1-2). Rows "
            "are sorted by lower bound, best first. By default only rows with y > 0 are shown."
        ),
        epilog=SHOW_EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    show.add_argument("path", type=Path, metavar="PATH", help="knowledge store (SQLite)")
    show.add_argument(
        "--type",
        dest="ref_type",
        metavar="T",
        help="only the relations of reference type or class T (a class pools its types)",
    )
    show.add_argument("--related", metavar="B", help="only rows about related type or class B")
    show.add_argument(
        "--backoff",
        action="store_true",
        help="types' intervals backed off to their class (knowledge/pooling.py): a type with "
        "little or no evidence borrows from its class instead of starting from [0, 1]; with "
        "--interval corrected, on the corrected intervals' effective counts",
    )
    show.add_argument("--all", action="store_true", help="also the rows with y = 0")
    show.add_argument("--json", action="store_true", help="print a JSON list of rows instead")
    show.add_argument(
        "--alpha",
        type=argtypes.alpha,
        default=None,
        help="alpha of the intervals (default: the store's)",
    )
    argtypes.add_interval_argument(show)
    _add_forget_args(show)
    _add_catalog_arg(show)
    show.set_defaults(func=run_show)


def _add_forget_args(p: argparse.ArgumentParser) -> None:
    """``--forget`` and its parameters, and ``--day`` (when the intervals are read)."""
    argtypes.add_forget_arguments(p)
    p.add_argument(
        "--day",
        type=argtypes.non_negative_int,
        default=None,
        metavar="T",
        help="with --forget: read the intervals as they stood at the end of day T (default: the "
        "last day in the store); the evidence of every run, by its day stamps",
    )


def _register_stats(kb_sub: argparse._SubParsersAction) -> None:
    """Add ``kb stats``."""
    stats = kb_sub.add_parser(
        "stats",
        help="summarise a store: examinations, runs, rooms, types examined, mean interval width",
        description=_wrap(
            "Summarise a knowledge store: examinations per run, rooms, how many types "
            "were examined, how many (relation, type) pairs were ever observed, and the mean "
            "interval width over every pair of the catalog (1.0 before any data)."
        ),
        epilog="example:\n  ctxsearch kb stats demo/kb.sqlite",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    stats.add_argument("path", type=Path, metavar="PATH", help="knowledge store (SQLite)")
    stats.add_argument("--json", action="store_true", help="print JSON instead")
    stats.add_argument(
        "--alpha",
        type=argtypes.alpha,
        default=None,
        help="alpha of the intervals (default: the store's)",
    )
    argtypes.add_interval_argument(stats)
    _add_forget_args(stats)
    _add_catalog_arg(stats)
    stats.set_defaults(func=run_stats)


def _register_merge(kb_sub: argparse._SubParsersAction) -> None:
    """Add ``kb merge``."""
    merge = kb_sub.add_parser(
        "merge",
        help="append the evidence of several stores to one (e.g. from several robots)",
        description=_wrap(
            "Append the examination logs of IN... to OUT (created if missing, appended "
            "to otherwise) in one transaction. All stores must be built on the same catalog; every "
            "input is checked before anything is written, and the inputs are not modified."
        ),
        epilog=MERGE_EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    merge.add_argument("out", type=Path, metavar="OUT", help="output store")
    merge.add_argument("inputs", type=Path, nargs="+", metavar="IN", help="input stores")
    _add_catalog_arg(merge)
    merge.set_defaults(func=run_merge)


def _register_maps(kb_sub: argparse._SubParsersAction) -> None:
    """Add ``kb maps``."""
    maps = kb_sub.add_parser(
        "maps",
        help="list the robot's remembered maps of the houses it visited on its own map",
        description=_wrap(
            "List the remembered map of every house visit a store holds (learning on the built "
            "map keeps one per visit done): run, style, seed, day, the furniture it recognised "
            "(and how many of them it saw in more than one examination), its rooms and how much "
            "of its grid it mapped as floor. `ctxsearch search --map remembered` searches on them."
        ),
        epilog="example:\n  ctxsearch kb maps demo/kb.sqlite",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    maps.add_argument("path", type=Path, metavar="PATH", help="knowledge store (SQLite)")
    maps.add_argument("--json", action="store_true", help="print JSON instead")
    _add_catalog_arg(maps)
    maps.set_defaults(func=run_maps)


def register_bench(sub: argparse._SubParsersAction) -> None:
    """Add ``bench kb``."""
    p = sub.add_parser(
        "kb",
        help="knowledge-base speed and memory at up to 100 000 types (HIF choice, record)",
        description=textwrap.dedent(
            """\
            Synthetic catalogs of T types with 6 relations each; per type and relation min(1% of T,
            --related) related types with a nonzero y.
            Times one Highest-Impact-First choice among 50 candidate types (cold: each candidate's
            score recomputed after a record_examination), one record_examination, and the peak
            traced memory; and, where it fits (T <= 1000), the same choice with a dense (T, 6, T)
            implementation. Medians over --reps repetitions. Writes DIR/bench_kb.json (a list of
            rows), DIR/bench_kb.csv (the same rows), DIR/bench_kb.md and DIR/bench_kb.png, and
            prints the table."""
        ),
        epilog=BENCH_EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "--out",
        type=argtypes.out_dir,
        default=None,
        metavar="DIR",
        help="write the files here (default: none, only the table is printed; make bench "
        "writes results/)",
    )
    p.add_argument(
        "--sizes",
        type=_sizes,
        default=None,
        help="comma-separated numbers of types (default: 100,1000,10000,30000,100000)",
    )
    p.add_argument(
        "--related",
        type=argtypes.non_negative_int,
        default=100,
        metavar="K",
        help="at most K related types per type and relation (0: no cap, 1%% of T) (default: 100)",
    )
    p.add_argument(
        "--reps", type=argtypes.positive_int, default=21, help="repetitions (default: 21)"
    )
    p.add_argument(
        "--candidates", type=argtypes.positive_int, default=50, help="candidate types (default: 50)"
    )
    p.add_argument("--seed", type=argtypes.seed, default=0, help="random seed (default: 0)")
    p.set_defaults(func=run_bench)


# ---- handlers ------------------------------------------------------------------------------
def _open_kb(args: argparse.Namespace, pooled: bool = False):
    """(facts about the store, its KnowledgeBase, its pooled counts if ``pooled`` else None) for
    args.path; StoreError if unusable."""
    catalog = load_catalog(args.catalog)
    try:
        with EvidenceStore.open(args.path, catalog, read_only=True) as store:
            kb = _forget_kb(args, store) or store.knowledge_base(args.alpha, interval=args.interval)
            pc = PooledCounts.from_store(store) if pooled else None
            info = {
                "path": str(args.path),
                "examinations": store.examinations_count(),
                "runs": {r: store.examinations_count(r) for r in store.runs()},
                "rooms": store.rooms(),
                "alpha": kb.alpha,
                "stored_alpha": float(store.meta["alpha"]),
                "catalog_fingerprint": store.fingerprint,
                "catalog": str(catalog.path),
                "created": store.meta.get("created", ""),
                "room_context": store.room_context(),
                "persistence": LearnedPersistence(store_checks(store), kb.alpha),
            }
    except sqlite3.DatabaseError as exc:  # damage found past the checks of open()
        raise StoreError(
            f"{args.path}: corrupt knowledge store ({' '.join(str(exc).split())})"
        ) from None
    return info, kb, pc


def _forget_kb(args: argparse.Namespace, store: EvidenceStore):
    """The store read with ``--forget`` (None for ``none``, the paper's counts)."""
    if args.forget == Forget.NONE:
        if args.day is not None:
            raise CtxsearchError("--day reads the intervals of a day: give it with --forget")
        return None
    if args.interval != IntervalMethod.WILSON:
        raise CtxsearchError(
            f"--forget {args.forget} does not combine with --interval {args.interval}"
        )
    evidence = evidence_of(store.examinations())
    today = evidence.last_day if args.day is None else args.day
    return ForgetKnowledgeBase(store.catalog, args.alpha if args.alpha is not None else store.alpha,
                               evidence, today, argtypes.forgetting(args))  # fmt: skip


def _count(v: float) -> str:
    """A count as printed: whole counts as integers, effective (forgetting) counts to 0.1."""
    return str(int(v)) if float(v).is_integer() else f"{v:.1f}"


def _row_dict(r) -> dict:
    return {
        "ref": r.ref,
        "relation": r.relation,
        "type": r.type,
        "y": r.y,
        "n": r.n,
        "p0": r.p0,
        "low": r.low,
        "high": r.high,
    }


def format_rows(rows) -> str:
    """The interval rows as an aligned text table."""
    head = ("relation", "type", "y/n", "low", "high")
    body = [
        (r.relation, r.type, f"{_count(r.y)}/{_count(r.n)}", f"{r.low:.3f}", f"{r.high:.3f}")
        for r in rows
    ]
    widths = [max(len(x) for x in col) for col in zip(head, *body, strict=True)]
    right = (False, False, True, True, True)

    def line(cells) -> str:
        return "  ".join(
            c.rjust(w) if rj else c.ljust(w) for c, w, rj in zip(cells, widths, right, strict=True)
        ).rstrip()

    return "\n".join([line(head), *(line(b) for b in body)])


@dataclass(frozen=True)
class RoomRow:
    """One SAME-ROOM-AS-F interval, printed like a relation's (knowledge.room_context)."""

    ref: str
    relation: str
    type: str
    y: int
    n: int
    p0: float
    low: float
    high: float


def room_rows(
    rc: RoomContext,
    catalog,
    ref: str | None,
    related: str | None,
    everything: bool,
    next_rooms: bool = False,
) -> list[RoomRow]:
    """The learned SAME-ROOM-AS-F intervals (with ``next_rooms``: NEXT-ROOM-OF-F, what lies
    through a door of a room holding F, n the pairs of rooms) of furniture type ``ref`` (or
    every one counted), for type ``related`` (or every type; y = 0 only with ``everything``),
    largest lower bound first."""
    counted = rc.next_n if next_rooms else rc.n
    interval = rc.next_interval if next_rooms else rc.interval
    read = rc.next_room if next_rooms else rc.same_room
    name = next_relation_name if next_rooms else relation_name
    refs = [ref] if ref is not None else sorted(counted)
    types = [related] if related is not None else list(catalog.type_names)
    out = []
    for f in refs:
        for t in types:
            got = interval(f, t)
            if got is None or (got[2] == 0 and not everything):
                continue
            lo, hi, y, n = got
            out.append(RoomRow(f, name(f), t, y, n, read(f, t, Rank.P0), lo, hi))
    return sorted(out, key=lambda r: (-r.low, r.relation, r.type))


def run_show(args: argparse.Namespace) -> int:
    """Handler of ``ctxsearch kb show``."""
    catalog = load_catalog(args.catalog)
    classes = catalog.hierarchy
    for name in (args.ref_type, args.related):
        if name is not None and name not in classes and name not in catalog:
            known = ", ".join(catalog.type_names)
            kinds = ", ".join(c.name for c in classes.classes) or "none"
            raise CatalogError(
                catalog.path, f"unknown type or class '{name}' (types: {known}; classes: {kinds})"
            )
    pooled = args.backoff or args.ref_type in classes or args.related in classes
    if pooled and args.forget != Forget.NONE:
        raise CtxsearchError(
            f"--forget {args.forget} reads types' own evidence: it does not combine with classes "
            "or --backoff"
        )
    if pooled and args.interval == IntervalMethod.CLUSTERED:
        raise CtxsearchError(
            "--interval clustered reads types' own evidence: it does not combine with classes "
            "or --backoff (--interval corrected does: it is clustered too)"
        )
    if args.interval == IntervalMethod.CORRECTED and args.related in classes:
        raise CtxsearchError(
            f"--interval corrected counts concrete related types, not the class {args.related}"
        )
    info, kb, pc = _open_kb(args, pooled=pooled)
    if pooled:
        rows = interval_rows(
            pc,
            kb.catalog,
            kb.alpha,
            ref=args.ref_type,
            related=args.related,
            include_zero=args.all,
            backoff=args.backoff,
            corrected=kb.corrected,
        )
    else:
        rows = kb.rows(args.ref_type, include_zero=args.all)
        if args.related is not None:
            rows = [r for r in rows if r.type == args.related]
    rc: RoomContext = info["room_context"]
    rooms, beyond = [], []
    if not pooled and args.forget == Forget.NONE:
        rooms = room_rows(rc, kb.catalog, args.ref_type, args.related, args.all)
        beyond = room_rows(rc, kb.catalog, args.ref_type, args.related, args.all, next_rooms=True)
    persist = []
    if not pooled and args.forget == Forget.NONE and args.related is None:
        learned: LearnedPersistence = info["persistence"]
        for t in [args.ref_type] if args.ref_type else learned.types():
            persist += learned.of_type(t)
    if args.json:
        extra = [dataclasses.asdict(e) | {"relation": STILL} for e in persist]
        _emit(json.dumps([_row_dict(r) for r in [*rows, *rooms, *beyond]] + extra, indent=1))
        return 0
    cat = kb.catalog
    class_names = tuple(c.name for c in classes.classes) if pooled else ()
    refs = [args.ref_type] if args.ref_type else (*cat.type_names, *class_names)
    n_rel = sum(
        len(classes.get(a).relations if a in classes else cat.type(a).relations) for a in refs
    )
    total = n_rel * (1 if args.related else len(cat) + len(class_names))
    shown_nonzero = sum(1 for r in rows if r.y > 0)
    out = [
        f"{info['path']}: {info['examinations']} examinations, alpha {kb.alpha:g}, "
        f"catalog {info['catalog_fingerprint']}"
        + ("" if args.interval == IntervalMethod.WILSON else f", {args.interval} intervals")
        + (
            ""
            if args.forget == Forget.NONE
            else f", forgetting {argtypes.forgetting(args).label} on day {kb.today}"
        )
    ]
    if rows:
        out.append(format_rows(rows))
    elif info["examinations"] == 0:
        out.append("no examinations yet (run `ctxsearch learn --kb PATH ...`)")
    else:
        out.append("no observed pairs" + (f" for type {args.ref_type}" if args.ref_type else ""))
    hidden = total - shown_nonzero if not args.all else 0
    if hidden:
        out.append(f"({hidden} rows with y = 0 hidden; --all shows them)")
    if rooms:
        out.append(f"room context: {rc.rooms} rooms of the robot's maps held furniture")
        out.append(format_rows(rooms))
    if beyond:
        pairs = sum(rc.next_n.values())
        out.append(
            "next rooms: what the room through a door of a room holding the furniture held "
            f"({pairs} pairs of a room and a room its doors lead to, a hall without furniture "
            "passed through, per furniture type, on the robot's maps)"
        )
        out.append(format_rows(beyond))
    if persist:
        out.append("persistence: the robot's checks of places where its maps saw small objects")
        out += listing(persist)
    _emit("\n".join(out))
    return 0


def run_maps(args: argparse.Namespace) -> int:
    """Handler of ``ctxsearch kb maps``."""
    catalog = load_catalog(args.catalog)
    rows = []
    try:
        with EvidenceStore.open(args.path, catalog, read_only=True) as store:
            for run, style, seed, day in store.home_maps():
                m = store.home_map(style, seed, run=run, upto_day=day)
                if m is None or m.day != day:
                    continue
                rows.append({
                    "run": run, "style": style, "seed": seed, "day": day,
                    "furniture": len(m.furniture),
                    "furniture_seen_twice": sum(1 for o in m.furniture if o.sightings >= 2),
                    "rooms": m.room_count(), "floor_share": round(float(m.floor.mean()), 4),
                    "images": m.images,
                })  # fmt: skip
    except sqlite3.DatabaseError as exc:
        raise StoreError(
            f"{args.path}: corrupt knowledge store ({' '.join(str(exc).split())})"
        ) from None
    if args.json:
        _emit(json.dumps(rows, indent=1))
        return 0
    if not rows:
        _emit(
            f"{args.path}: no remembered maps (learn on the built map: ctxsearch learn --kb PATH)"
        )
        return 0
    out = [f"{args.path}: {len(rows)} remembered map(s)"]
    for r in rows:
        out.append(
            f"  {r['style']} seed {r['seed']} day {r['day']} ({r['run']}): {r['furniture']} "
            f"furniture ({r['furniture_seen_twice']} seen twice or more), {r['rooms']} rooms, "
            f"{100 * r['floor_share']:.0f}% of the grid floor, {r['images']} images"
        )
    _emit("\n".join(out))
    return 0


def run_stats(args: argparse.Namespace) -> int:
    """Handler of ``ctxsearch kb stats``."""
    info, kb, _ = _open_kb(args)
    cat = kb.catalog
    n_by_type = {t: kb.n(t) for t in cat.type_names if kb.n(t) > 0}
    pairs_total = sum(len(t.relations) for t in cat.types) * len(cat)
    done = sum(1 for r in info["rooms"] if r[3] == "done")
    stats = {
        "path": info["path"],
        "examinations": info["examinations"],
        "runs": info["runs"],
        "rooms_done": done,
        "rooms_started": len(info["rooms"]) - done,
        "types": len(cat),
        "types_examined": len(n_by_type),
        "n_by_type": n_by_type,
        "pairs": pairs_total,
        "pairs_observed": kb.nnz(),
        "mean_width": kb.mean_width(),
        "alpha": kb.alpha,
        "catalog_fingerprint": info["catalog_fingerprint"],
        "created": info["created"],
    }
    if args.json:
        _emit(json.dumps(stats, indent=1))
        return 0
    runs = ", ".join(f"{r} ({c})" for r, c in info["runs"].items()) or "none"
    top = sorted(n_by_type.items(), key=lambda kv: (-kv[1], kv[0]))
    examined = ", ".join(f"{t} {c}" for t, c in top[:12]) + (" ..." if len(top) > 12 else "")
    lines = [
        ("store", f"{info['path']} (created {info['created']})"),
        ("catalog", f"{info['catalog_fingerprint']} ({info['catalog']})"),
        ("examinations", f"{info['examinations']} (runs: {runs})"),
        ("rooms", f"{done} done, {len(info['rooms']) - done} started"),
        ("types examined", f"{len(n_by_type)} of {len(cat)}" + (f": {examined}" if top else "")),
        ("pairs with y > 0", f"{kb.nnz()} of {pairs_total}"),
        ("mean width", f"{kb.mean_width():.4f} (alpha {kb.alpha:g}; 1.0 = nothing known)"),
    ]
    w = max(len(k) for k, _ in lines)
    _emit("\n".join(f"{k.ljust(w)}  {v}" for k, v in lines))
    return 0


def run_merge(args: argparse.Namespace) -> int:
    """Handler of ``ctxsearch kb merge``."""
    catalog = load_catalog(args.catalog)
    added = merge_stores(args.out, args.inputs, catalog)
    with EvidenceStore.open(args.out, catalog, create=False) as store:
        total = store.examinations_count()
    print(
        f"merged {added} examinations from {len(args.inputs)} store(s) into {args.out} "
        f"(now {total} examinations)"
    )
    return 0


def run_bench(args: argparse.Namespace) -> int:
    """Handler of ``ctxsearch bench kb``."""
    # Imported here: the benchmark pulls in matplotlib, which `kb show` must not wait for.
    from ctxsearch.scripts.experiments import bench_kb as bench

    sizes = args.sizes or bench.DEFAULT_SIZES

    def progress(row: dict) -> None:
        print(
            f"  T={row['types']:>6}: choose {row['choose_ms']:.3f} ms, record {row['record_ms']:.3f} ms, "
            f"peak {row['peak_mb']:.1f} MB",
            file=sys.stderr,
            flush=True,
        )

    rows = bench.run(
        tuple(sizes),
        reps=args.reps,
        candidates=args.candidates,
        seed=args.seed,
        progress=progress,
        max_related=args.related or None,
    )
    command = (
        f"ctxsearch bench kb --out {args.out} --sizes {','.join(str(t) for t in sizes)} "
        f"--reps {args.reps} --candidates {args.candidates} --seed {args.seed} "
        f"--related {args.related}"
    )
    print(bench.markdown_table(rows))
    if args.out is None:  # a benchmark without --out writes nothing
        print("no files written (--out DIR writes bench_kb.json, .csv, .md and .png)")
        return 0
    paths = bench.write_results(rows, args.out, command=command)
    print(f"wrote {paths['json']}, {paths['csv']}, {paths['md']} and {paths['png']}")
    return 0

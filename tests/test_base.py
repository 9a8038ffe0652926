"""The knowledge base: counts, "at least one", intervals on demand, HIF scores and choice."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from ctxsearch.knowledge import intervals
from ctxsearch.knowledge.base import KnowledgeBase
from ctxsearch.knowledge.catalog import Catalog, ObjectType, RelationSpec
from ctxsearch.knowledge.errors import CtxsearchError

_U = (-0.5, -0.5, -0.5)
_V = (0.5, 0.5, 0.5)


def make_catalog(spec: dict[str, list[str]]) -> Catalog:
    """An in-memory catalog: {type name: [relation prefixes]} (e.g. {"Desk": ["ON-TOP-OF", "NEAR"]})."""
    types = []
    for name, rels in spec.items():
        relations = tuple(RelationSpec(f"{r}-{name.upper()}", name, _U, _V) for r in rels)
        types.append(
            ObjectType(
                name, "object", "box", (1, 1, 1), (1, 1, 1), (0.5, 0.5, 0.5), 10, 5.0, relations
            )
        )
    return Catalog(tuple(types))


@pytest.fixture
def cat() -> Catalog:
    return make_catalog(
        {"Desk": ["ON-TOP-OF", "UNDER", "NEAR"], "Cup": ["NEAR"], "Book": [], "Chair": ["NEAR"]}
    )


def brute_force_score(kb: KnowledgeBase, ref: str, fn=intervals.impact) -> float:
    """Figure 2 line 11 the slow way: average fn(y, n_A) over every rel of A and every type t."""
    rels = kb.catalog.type(ref).relation_names
    if not rels:
        return 0.0
    vals = [float(fn(kb.y(r, t), kb.n(ref), kb.alpha)) for r in rels for t in kb.catalog.type_names]
    return float(np.mean(vals))


def test_counts_start_at_zero(cat):
    kb = KnowledgeBase(cat)
    assert kb.alpha == 0.10
    assert all(kb.n(t) == 0 for t in cat.type_names)
    assert kb.y("NEAR-CUP", "Desk") == 0
    assert kb.total_examinations == 0
    assert kb.nonzero("Desk") == {}
    assert kb.interval("ON-TOP-OF-DESK", "Cup") == (0.0, 1.0)


def test_record_counts_and_at_least_one(cat):
    kb = KnowledgeBase(cat)
    # Two cups on one desk: the pair is listed twice but counts once.
    kb.record_examination(
        "Desk", [("ON-TOP-OF-DESK", "Cup"), ("ON-TOP-OF-DESK", "Cup"), ("NEAR-DESK", "Chair")]
    )
    kb.record_examination("Desk", [("ON-TOP-OF-DESK", "Cup")])
    kb.record_examination("Desk", [])
    kb.record_examination("Cup", iter([("NEAR-CUP", "Desk")]))
    assert kb.n("Desk") == 3 and kb.n("Cup") == 1 and kb.n("Chair") == 0
    assert kb.y("ON-TOP-OF-DESK", "Cup") == 2
    assert kb.y("NEAR-DESK", "Chair") == 1
    assert kb.y("UNDER-DESK", "Chair") == 0
    assert kb.y("NEAR-CUP", "Desk") == 1
    assert kb.total_examinations == 4
    assert kb.nonzero("Desk") == {("ON-TOP-OF-DESK", "Cup"): 2, ("NEAR-DESK", "Chair"): 1}
    lo, hi = kb.interval("ON-TOP-OF-DESK", "Cup")
    assert (lo, hi) == pytest.approx(tuple(float(v) for v in intervals.interval(2, 3)))


def test_record_rejects_bad_input_without_changing_counts(cat):
    kb = KnowledgeBase(cat)
    kb.record_examination("Desk", [("NEAR-DESK", "Cup")])
    before = (kb.n("Desk"), kb.nonzero("Desk"))
    with pytest.raises(CtxsearchError, match="not a relation of Desk"):
        kb.record_examination("Desk", [("NEAR-DESK", "Cup"), ("NEAR-CUP", "Desk")])
    with pytest.raises(CtxsearchError, match="unknown type 'Mug'"):
        kb.record_examination("Desk", [("NEAR-DESK", "Mug")])
    with pytest.raises(CtxsearchError, match="unknown relation"):
        kb.record_examination("Desk", [("BEHIND-DESK", "Cup")])
    with pytest.raises(CtxsearchError, match="unknown type"):
        kb.record_examination("Mug", [])
    assert (kb.n("Desk"), kb.nonzero("Desk")) == before


def test_unobserved_intervals_follow_n(cat):
    """Figure 2 line 20 updates only observed pairs; ours derive every interval from the counts."""
    kb = KnowledgeBase(cat)
    widths = []
    for _ in range(5):
        kb.record_examination("Desk", [("NEAR-DESK", "Chair")])
        lo, hi = kb.interval("UNDER-DESK", "Book")  # never observed
        assert lo == 0.0
        widths.append(hi - lo)
        assert (lo, hi) == pytest.approx(
            tuple(float(v) for v in intervals.interval(0, kb.n("Desk")))
        )
    assert all(a > b for a, b in itertools.pairwise(widths))
    # Other reference types are untouched.
    assert kb.interval("NEAR-CUP", "Book") == (0.0, 1.0)


def _random_kb(cat: Catalog, seed: int, steps: int = 60) -> KnowledgeBase:
    rng = np.random.default_rng(seed)
    kb = KnowledgeBase(cat)
    refs = [t for t in cat.type_names if cat.type(t).relations]
    for _ in range(steps):
        ref = refs[rng.integers(len(refs))]
        rels = cat.type(ref).relation_names
        k = rng.integers(0, 4)
        pairs = [
            (rels[rng.integers(len(rels))], cat.type_names[rng.integers(len(cat))])
            for _ in range(k)
        ]
        kb.record_examination(ref, pairs)
    return kb


@pytest.mark.parametrize("seed", range(5))
def test_type_impact_equals_brute_force(cat, seed):
    kb = _random_kb(cat, seed)
    for t in cat.type_names:
        assert kb.type_impact(t) == pytest.approx(brute_force_score(kb, t), abs=1e-12)
        assert kb.type_score(t, intervals.expected_width_change) == pytest.approx(
            brute_force_score(kb, t, intervals.expected_width_change), abs=1e-12
        )


def test_type_impact_of_unexamined_type_is_impact_0_0(cat):
    kb = KnowledgeBase(cat)
    assert kb.type_impact("Desk") == pytest.approx(0.2699, abs=1e-4)
    assert kb.type_impact("Book") == 0.0  # no relations: examining it teaches nothing


def test_scores_are_invalidated_on_record(cat):
    kb = KnowledgeBase(cat)
    first = kb.type_impact("Desk")
    assert kb.type_impact("Desk") == first  # cached
    kb.record_examination("Desk", [])
    assert kb.type_impact("Desk") == pytest.approx(float(intervals.impact(0, 1)))
    kb.record_examination("Desk", [("NEAR-DESK", "Cup")])
    assert kb.type_impact("Desk") == pytest.approx(brute_force_score(kb, "Desk"), abs=1e-12)


def test_choose_is_highest_impact_first_with_deterministic_tie_break(cat):
    kb = KnowledgeBase(cat)
    # All unseen: a tie, broken by catalog order whatever the candidates' order.
    for perm in itertools.permutations(["Chair", "Cup", "Desk"]):
        assert kb.choose(perm) == "Desk"
    assert kb.choose(["Chair", "Cup", "Cup"]) == "Cup"
    # After two examinations of Desk, impact(0, 2) = 0.1008 < impact(0, 0): an unseen type wins.
    kb.record_examination("Desk", [])
    kb.record_examination("Desk", [])
    assert kb.choose(["Desk", "Chair"]) == "Chair"
    assert kb.choose(["Desk"]) == "Desk"
    # A type without relations never wins against one with relations.
    assert kb.choose(["Book", "Desk"]) == "Desk"
    with pytest.raises(CtxsearchError):
        kb.choose([])
    with pytest.raises(CtxsearchError, match="unknown type"):
        kb.choose(["Desk", "Mug"])


def test_choose_matches_brute_force_argmax(cat):
    kb = _random_kb(cat, 11, steps=25)
    cands = list(cat.type_names)
    scores = [brute_force_score(kb, t) for t in cands]
    best = max(scores)
    expect = next(t for t, s in zip(cands, scores, strict=True) if abs(s - best) < 1e-12)
    assert kb.choose(cands[::-1]) == expect


def test_rows_are_sorted_and_cover_every_pair(cat):
    kb = _random_kb(cat, 3)
    rows = kb.rows()
    n_pairs = sum(len(t.relations) for t in cat.types) * len(cat)
    assert len(rows) == n_pairs
    assert [r.low for r in rows] == sorted((r.low for r in rows), reverse=True)
    for r in rows:
        assert r.y == kb.y(r.relation, r.type) and r.n == kb.n(r.ref)
        assert (r.low, r.high) == pytest.approx(kb.interval(r.relation, r.type))
        assert r.width == pytest.approx(r.high - r.low)
        assert r.low <= r.p0 <= r.high
    nz = kb.rows(include_zero=False)
    assert {(r.relation, r.type) for r in nz} == {k for t in cat.type_names for k in kb.nonzero(t)}
    assert all(r.ref == "Desk" for r in kb.rows("Desk"))
    assert len(kb.rows("Book")) == 0


def test_mean_width_equals_brute_force(cat):
    kb = _random_kb(cat, 5)
    rows = kb.rows()
    assert kb.mean_width() == pytest.approx(float(np.mean([r.width for r in rows])), abs=1e-12)
    assert KnowledgeBase(cat).mean_width() == pytest.approx(1.0)


def test_add_counts_merges_and_checks(cat):
    a, b = _random_kb(cat, 1), _random_kb(cat, 2)
    merged = KnowledgeBase(cat)
    for kb in (a, b):
        for t in cat.type_names:
            merged.add_counts(t, kb.n(t), kb.nonzero(t))
    for t in cat.type_names:
        assert merged.n(t) == a.n(t) + b.n(t)
        assert merged.type_impact(t) == pytest.approx(brute_force_score(merged, t), abs=1e-12)
    for rel in cat.relations:
        for t in cat.type_names:
            assert merged.y(rel.name, t) == a.y(rel.name, t) + b.y(rel.name, t)
    with pytest.raises(CtxsearchError, match="y exceeds n"):
        KnowledgeBase(cat).add_counts("Desk", 1, {("NEAR-DESK", "Cup"): 2})


def test_alpha_is_validated_and_used(cat):
    with pytest.raises(ValueError):
        KnowledgeBase(cat, alpha=1.5)
    kb = KnowledgeBase(cat, alpha=0.05)
    kb.record_examination("Desk", [("NEAR-DESK", "Cup")])
    assert kb.interval("NEAR-DESK", "Cup") == pytest.approx(
        tuple(float(v) for v in intervals.interval(1, 1, 0.05))
    )


# ---- the compact storage against a plain reference model ---------------------------------------
class DictModel:
    """The obvious implementation: dicts of counts."""

    def __init__(self, cat: Catalog):
        self.cat = cat
        self.n = dict.fromkeys(cat.type_names, 0)
        self.y: dict[tuple[str, str], int] = {}

    def record(self, ref: str, pairs) -> None:
        self.n[ref] += 1
        for key in set(pairs):
            self.y[key] = self.y.get(key, 0) + 1


def test_random_operations_match_a_dict_model():
    rng = np.random.default_rng(42)
    spec = {f"Ty{i}": ["NEAR", "UNDER", "ON-TOP-OF", "LEFT-OF"][: i % 5] for i in range(40)}
    cat = make_catalog(spec)
    kb, model = KnowledgeBase(cat), DictModel(cat)
    refs = [t for t in cat.type_names if cat.type(t).relations]
    for step in range(600):
        ref = refs[rng.integers(len(refs))]
        rels = cat.type(ref).relation_names
        pairs = [
            (rels[rng.integers(len(rels))], cat.type_names[rng.integers(8)])
            for _ in range(rng.integers(0, 6))
        ]
        kb.record_examination(ref, pairs)
        model.record(ref, pairs)
        if step in (0, 299, 599):
            for t in cat.type_names:
                assert kb.type_impact(t) == pytest.approx(brute_force_score(kb, t), abs=1e-12)
    for t in cat.type_names:
        assert kb.n(t) == model.n[t]
        expect = {k: v for k, v in model.y.items() if cat.relation(k[0]).ref == t}
        assert kb.nonzero(t) == expect
        assert kb.nnz(t) == len(expect)
    for (rel, t), v in model.y.items():
        assert kb.y(rel, t) == v
    assert kb.nnz() == len(model.y)
    assert kb.total_examinations == 600


def test_fast_impact_equals_intervals_impact():
    from ctxsearch.knowledge.base import _impact_fixed_n

    for alpha in (0.10, 0.05):
        for n in (0, 1, 2, 3, 7, 50, 999):
            y = np.arange(n + 1, dtype=float)
            np.testing.assert_allclose(
                _impact_fixed_n(y, n, alpha), intervals.impact(y, n, alpha), rtol=0, atol=1e-14
            )


def test_impact_is_symmetric_so_scores_fold_y_onto_min_y_n_minus_y(cat):
    """The HIF score evaluates eq. 3 once per min(y, n - y): that is exact because impact(y, n)
    = impact(n - y, n); a type whose counts sit above n / 2 scores as the brute force does."""
    for alpha in (0.10, 0.05):
        for n in (1, 2, 3, 8, 51, 1000):
            y = np.arange(n + 1, dtype=float)
            np.testing.assert_allclose(
                intervals.impact(y, n, alpha), intervals.impact(n - y, n, alpha), rtol=0, atol=1e-15
            )
    kb = KnowledgeBase(cat)
    kb.add_counts("Desk", 40, {("NEAR-DESK", "Cup"): 39, ("UNDER-DESK", "Chair"): 40})
    kb.add_counts("Cup", 5000, {("NEAR-CUP", "Desk"): 4990, ("NEAR-CUP", "Book"): 7})  # listed
    for t in ("Desk", "Cup"):
        assert kb.type_impact(t) == pytest.approx(brute_force_score(kb, t), abs=1e-12)


def test_large_n_with_few_nonzero_and_dtype_promotion(cat):
    kb = KnowledgeBase(cat)
    kb.add_counts("Desk", 5000, {("NEAR-DESK", "Cup"): 4999, ("UNDER-DESK", "Chair"): 3})
    assert kb.type_impact("Desk") == pytest.approx(brute_force_score(kb, "Desk"), abs=1e-12)
    kb.add_counts("Cup", 65535, {("NEAR-CUP", "Desk"): 65535})
    kb.record_examination("Cup", [("NEAR-CUP", "Desk")])  # n and y pass 65535 (uint16)
    kb.record_examination("Cup", [("NEAR-CUP", "Book")])
    assert kb.n("Cup") == 65537
    assert kb.y("NEAR-CUP", "Desk") == 65536 and kb.y("NEAR-CUP", "Book") == 1
    kb.add_counts("Chair", 10**10, {("NEAR-CHAIR", "Desk"): 10**10 - 1})
    assert kb.y("NEAR-CHAIR", "Desk") == 10**10 - 1
    assert kb.type_impact("Chair") == pytest.approx(brute_force_score(kb, "Chair"), abs=1e-12)


def test_add_count_arrays_sums_repeats_and_validates(cat):
    kb = KnowledgeBase(cat)
    names = cat.type_names  # Desk, Cup, Book, Chair
    kb.add_count_arrays("Desk", 10, [2, 0, 2, 1], [1, 3, 1, 0], [3, 1, 4, 0])
    assert kb.n("Desk") == 10
    assert kb.nonzero("Desk") == {("NEAR-DESK", "Cup"): 7, ("ON-TOP-OF-DESK", "Chair"): 1}
    kb.add_count_arrays("Desk", 2, [2], [names.index("Cup")], [1])
    assert kb.y("NEAR-DESK", "Cup") == 8 and kb.n("Desk") == 12
    before = kb.nonzero("Desk")
    for bad in (
        dict(n=1, rel_index=[3], type_index=[0], y=[1]),  # Desk has 3 relations
        dict(n=1, rel_index=[0], type_index=[4], y=[1]),  # 4 types
        dict(n=1, rel_index=[0], type_index=[0], y=[-1]),
        dict(n=0, rel_index=[2], type_index=[1], y=[5]),  # y would exceed n
        dict(n=1, rel_index=[0, 1], type_index=[0], y=[1]),
    ):
        with pytest.raises(CtxsearchError):
            kb.add_count_arrays("Desk", **bad)
    assert kb.nonzero("Desk") == before and kb.n("Desk") == 12
    with pytest.raises(CtxsearchError, match="not a relation of Desk"):
        kb.add_counts("Desk", 1, {("NEAR-CUP", "Desk"): 1})


def test_more_than_65536_types():
    from ctxsearch.scripts.experiments.bench_kb import synthetic_catalog

    cat = synthetic_catalog(70_000, relations_per_type=1)
    kb = KnowledgeBase(cat)
    last, first = cat.type_names[-1], cat.type_names[0]
    rel = cat.type(first).relation_names[0]
    kb.record_examination(first, [(rel, last), (rel, cat.type_names[66_000])])
    assert kb.y(rel, last) == 1 and kb.y(rel, cat.type_names[66_000]) == 1 and kb.y(rel, first) == 0
    assert kb.type_impact(first) == pytest.approx(
        ((70_000 - 2) * float(intervals.impact(0, 1)) + 2 * float(intervals.impact(1, 1))) / 70_000
    )
    assert kb.choose([last, first]) == last  # unseen: impact(0, 0) is the largest


def test_clear_cache_forces_recomputation(cat):
    kb = KnowledgeBase(cat)
    kb.record_examination("Desk", [("NEAR-DESK", "Cup")])
    s = kb.type_impact("Desk")
    kb._score_cache[0][intervals.impact] = -1.0
    assert kb.type_impact("Desk") == -1.0
    kb.clear_cache()
    assert kb.type_impact("Desk") == s


@pytest.mark.parametrize("seed", range(4))
def test_a_choice_scores_its_candidates_at_once_bit_for_bit(seed):
    """``choose`` computes the uncached candidates' d_A in one numpy pass (``_impact_scores``):
    every score equals the one-type computation exactly, on both of its paths (few distinct
    counts, and many), for unseen types and types without relations."""
    rng = np.random.default_rng(seed)
    spec = {f"T{i}": ["ON", "NEAR"][: int(rng.integers(0, 3))] for i in range(40)}
    cat = make_catalog(spec)
    kb = KnowledgeBase(cat)
    names = cat.type_names
    for _ in range(300):
        ref = names[int(rng.integers(0, 25))]  # the last 15 types stay unseen
        rels = cat.type(ref).relation_names
        pairs = [(rels[int(rng.integers(0, len(rels)))], names[int(rng.integers(0, 40))])
                 for _ in range(int(rng.integers(0, 6)))] if rels else []  # fmt: skip
        kb.record_examination(ref, pairs)
    heavy = next(t for t in names if cat.type(t).relation_names)
    for _ in range(400):  # n_A far above its nonzero counts: the other path
        kb.record_examination(heavy, [])
    assert kb.n(heavy) > 4 * len(kb.nonzero(heavy)) + 64
    kb.choose(names)  # batch: fills the cache
    batch = {t: kb.type_impact(t) for t in names}
    kb.clear_cache()
    single = {t: kb.type_impact(t) for t in names}  # one type at a time
    assert batch == single
    assert kb.choose(names) == max(names, key=lambda t: (single[t], -names.index(t)))

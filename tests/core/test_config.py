"""core.config: configs built from mappings by their annotations; every error names the key."""

from __future__ import annotations

import doctest
from dataclasses import dataclass, field
from typing import Any, Literal

import pytest

import core.config
from core.config import bounded, check_arguments, from_mapping
from core.errors import RigError


@dataclass(frozen=True)
class Solver:
    max_iterations: int = bounded(30, min=1, max=1000)
    tolerance: float = bounded(1e-4, above=0.0)
    kind: Literal["block", "dense"] = "block"


@dataclass(frozen=True)
class Settings:
    name: str
    gamma: tuple[float, float, float] = bounded((3.0, 4.0, 0.01), min=0.0)
    rings: tuple[float, ...] = bounded((20.0,), min=-90, max=90, min_items=1)
    levels: dict[str, float] = bounded(default_factory=dict, max=1)
    focal_px: float | None = None
    verbose: bool = False
    mode: bool | Literal["auto"] = "auto"
    solver: Solver = field(default_factory=Solver)
    pairs: tuple[Solver, ...] = ()


def build(data: Any) -> Settings:
    return from_mapping(Settings, data, "run.yaml", "optimise")


def error(data: Any) -> str:
    with pytest.raises(RigError) as caught:
        build(data)
    assert caught.value.fix and caught.value.fix.startswith("allowed: ")
    return str(caught.value)


def test_the_docstring_examples_hold() -> None:
    assert doctest.testmod(core.config, optionflags=doctest.ELLIPSIS).failed == 0


def test_values_are_converted_and_defaults_kept() -> None:
    s = build({"name": "a", "gamma": [1, 2, 3], "rings": [10, -20.5], "levels": {"r": 0.5}})
    assert s.gamma == (1.0, 2.0, 3.0) and all(type(g) is float for g in s.gamma)
    assert s.rings == (10.0, -20.5) and s.levels == {"r": 0.5}
    assert s.solver == Solver() and s.focal_px is None and s.mode == "auto"
    assert build({"name": "a", "focal_px": 800}).focal_px == 800.0


def test_nested_dataclasses_and_lists_of_them() -> None:
    s = build({"name": "a", "solver": {"kind": "dense"}, "pairs": [{"max_iterations": 2}]})
    assert s.solver.kind == "dense" and s.pairs == (Solver(max_iterations=2),)
    assert build({"name": "a", "solver": None}).solver == Solver()  # an empty YAML section
    same = Solver(kind="dense")
    assert build({"name": "a", "solver": same}).solver is same
    zero = {"name": "a", "solver": {"max_iterations": 0}}
    assert "'optimise.solver.max_iterations' is 0" in error(zero)
    assert "'optimise.pairs[1].kind' is 'sparse'" in error(
        {"name": "a", "pairs": [{}, {"kind": "sparse"}]}
    )


def test_literal_choices_are_listed() -> None:
    message = error({"name": "a", "solver": {"kind": "amg"}})
    assert "'optimise.solver.kind' is 'amg'" in message and "allowed: block, dense" in message
    assert build({"name": "a", "mode": True}).mode is True
    assert "true or false or auto" in error({"name": "a", "mode": "yes"})


def test_bounds_come_from_the_field_metadata() -> None:
    assert "a whole number in [1, 1000]" in error({"name": "a", "solver": {"max_iterations": 1001}})
    assert "a finite number > 0" in error({"name": "a", "solver": {"tolerance": 0.0}})
    assert "'optimise.gamma' is [1, -2, 3]" in error({"name": "a", "gamma": [1, -2, 3]})
    assert "'optimise.rings' is [100]" in error({"name": "a", "rings": [100]})
    assert "at least 1" in error({"name": "a", "rings": []})
    assert "'optimise.levels.r' is 1.5" in error({"name": "a", "levels": {"r": 1.5}})


def test_bool_is_not_a_number_and_a_number_is_not_a_bool() -> None:
    assert "'optimise.solver.max_iterations' is True" in error(
        {"name": "a", "solver": {"max_iterations": True}}
    )
    assert "'optimise.verbose' is 1 — allowed: true or false" in error({"name": "a", "verbose": 1})
    assert "'optimise.solver.max_iterations' is 2.5" in error(
        {"name": "a", "solver": {"max_iterations": 2.5}}
    )
    assert "'optimise.focal_px' is nan" in error({"name": "a", "focal_px": float("nan")})
    assert "'optimise.name' is 3" in error({"name": 3})


def test_none_only_where_the_annotation_allows_it() -> None:
    assert build({"name": "a", "focal_px": None}).focal_px is None
    assert "or null" in error({"name": "a", "focal_px": "far"})
    assert "'optimise.verbose' is None" in error({"name": "a", "verbose": None})


def test_wrong_lengths_and_shapes() -> None:
    assert "a list of 3, each" in error({"name": "a", "gamma": [1, 2]})
    assert "a mapping" in error({"name": "a", "levels": [0.5]})
    assert "'optimise' is 'fast'" in error("fast")


def test_unknown_keys_suggest_the_nearest() -> None:
    message = error({"name": "a", "solver": {"max_iteration": 3}})
    assert "'optimise.solver.max_iteration' is not known" in message
    assert "(did you mean 'max_iterations'?)" in message
    assert "allowed: max_iterations, tolerance, kind" in message
    assert "did you mean" not in error({"name": "a", "zzz": 1})


def test_missing_required_key() -> None:
    assert "run.yaml: key 'optimise.name' is missing" in error({})


def test_check_arguments_follows_the_signature() -> None:
    def make(port: object, baudrate: int = 9600, *, mode: Literal["a", "b"] = "a",
             timeout_s: float | None = None) -> None:
        del port, baudrate, mode, timeout_s

    check_arguments(make, {"baudrate": 57600, "mode": "b"}, "light driver 'x'", skip=1)
    with pytest.raises(RigError, match="key 'baudrat' is not known \\(did you mean 'baudrate'"):
        check_arguments(make, {"baudrat": 1}, "light driver 'x'", skip=1)
    with pytest.raises(RigError, match="key 'port' is missing"):
        check_arguments(make, {}, "light driver 'x'")
    with pytest.raises(RigError, match="light driver 'x': key 'mode' is 'c' — allowed: a, b"):
        check_arguments(make, {"mode": "c"}, "light driver 'x'", skip=1)
    with pytest.raises(RigError, match="key 'baudrate' is True"):
        check_arguments(make, {"baudrate": True}, "light driver 'x'", skip=1)

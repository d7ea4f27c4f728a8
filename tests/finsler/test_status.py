"""One family of statuses (issue 23, part 5): every outcome enum of the toolkit derives
from :class:`solvers.Outcome`, says ``converged`` and prints its label."""

from __future__ import annotations

import enum
import importlib
import pkgutil

import pytest

import finsler.status
import solvers
from solvers import Outcome
from solvers.status import families


def _status_enums_in_packages() -> set[type]:
    found: set[type] = set()
    for pkg_name in ("finsler", "solvers", "learn", "validation"):
        pkg = importlib.import_module(pkg_name)
        for info in pkgutil.walk_packages(pkg.__path__, prefix=f"{pkg_name}."):
            mod = importlib.import_module(info.name)
            for obj in vars(mod).values():
                if (isinstance(obj, type) and issubclass(obj, enum.Enum)
                        and (issubclass(obj, Outcome) or obj.__name__.endswith(
                            ("Status", "Outcome", "Stop")))
                        and obj is not Outcome):
                    found.add(obj)
    return found


def test_every_status_enum_is_one_family() -> None:
    found = _status_enums_in_packages()
    assert found, "the scan found no status enum"
    assert found == set(families()), found ^ set(families())
    assert all(issubclass(f, Outcome) for f in found)


@pytest.mark.parametrize("family", families(), ids=lambda f: f.__name__)
def test_members_have_labels_and_converged(family: type[Outcome]) -> None:
    labels = [m.label for m in family]
    assert len(set(labels)) == len(labels)
    for member in family:
        # the property suite's "not-run" keeps the hyphen of its JSON
        assert member.label in (member.name.lower(), member.name.lower().replace("_", "-"))
        assert str(member) == member.label
        assert isinstance(member.converged, bool)
    assert any(m.converged for m in family) and not all(m.converged for m in family)


def test_shared_names_mean_the_same() -> None:
    # a name used by two families has the same convergence verdict in both
    verdicts: dict[str, set[bool]] = {}
    for family in families():
        for m in family:
            verdicts.setdefault(m.label, set()).add(m.converged)
    assert {k: v for k, v in verdicts.items() if len(v) > 1} == {}


def test_public_api_exports_the_family() -> None:
    for family in families():
        assert getattr(finsler.status, family.__name__) is family  # the ground layer
        if family.__name__ not in ("NewtonStatus", "CertifyStop", "LPStatus",
                                   "PropertyOutcome", "RunStop", "RunStatus", "RunAction",
                                   "EvalStatus", "SearchStatus", "SweepStatus"):
            # NewtonStatus is internal to the batched solver; CertifyStop and LPStatus come
            # with a CertifyResult, PropertyOutcome with the property suite, the Run*,
            # Eval, Search and Sweep families with learn's results
            assert getattr(solvers, family.__name__) is family
    assert solvers.Status.from_ipopt("Solve_Succeeded") is solvers.Status.SUCCESS
    assert solvers.Status.SUCCESS.label == "success"

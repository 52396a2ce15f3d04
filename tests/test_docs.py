"""The API reference is generated from the docstrings (mkdocs.yml; built with --strict by
scripts/test.sh, where griffe refuses an ``Args:`` entry naming no parameter). These tests keep
the other direction: every parameter of a scene and of a Material is documented, the shared
vocabulary once (:class:`granflow.scenes.SceneParameters`), the rest in the scene's ``Args:``
section."""

from __future__ import annotations

import dataclasses
import re

import pytest
from granflow.material import Material
from granflow.scenes import SCENES, SceneParameters
from granflow.scenes._base import MATERIAL_KEYS

#: the parameters every scene shares, documented once (SceneParameters)
SHARED = {f.name for f in dataclasses.fields(SceneParameters)}


def documented_args(doc: str) -> set[str]:
    """The names of a Google-style ``Args:`` section of ``doc``."""
    m = re.search(r"^( *)Args:\n((?:\1 {4}.*\n|\s*\n)*)", doc + "\n", re.M)
    if m is None:
        return set()
    indent = len(m.group(1)) + 4
    return {line[indent:].split(":", 1)[0] for line in m.group(2).splitlines()
            if len(line) > indent and line[indent] != " " and ":" in line}


def test_documented_args_reads_a_google_section():
    doc = """Summary.

    Args:
        a: one.
        b: two,
            continued: not a name.

    Returns:
        nothing.
    """
    assert documented_args(doc) == {"a", "b"}
    assert documented_args("No section.") == set()


@pytest.mark.parametrize("name", sorted(SCENES))
def test_every_scene_parameter_is_documented(name):
    cls = SCENES[name]
    assert issubclass(cls, SceneParameters)
    own = {f.name for f in dataclasses.fields(cls)} - SHARED
    # a scene built on another (RateCell on ShearCell) documents only what it adds
    documented = set().union(*(documented_args(c.__doc__ or "") for c in cls.__mro__
                               if c in SCENES.values()))
    missing = own - documented
    assert not missing, f"{cls.__name__}: parameters without an Args entry: {sorted(missing)}"
    assert "sample_every" in own  # every scene samples, each with its own default


def test_the_shared_vocabulary_is_documented_once():
    assert documented_args(SceneParameters.__doc__ or "") == SHARED
    # the flat material overrides are the material's own field names
    assert set(MATERIAL_KEYS) <= SHARED & {f.name for f in dataclasses.fields(Material)}


def test_every_material_field_is_documented():
    fields = {f.name for f in dataclasses.fields(Material)}
    assert fields == documented_args(Material.__doc__ or "")

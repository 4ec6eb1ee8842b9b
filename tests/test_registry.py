"""The one registry mechanism (spikectl.registry): register once, look up by name."""

import pytest

from spikectl.registry import Registry, RegistryError, load_target


class Thing:
    pass


def test_register_then_look_up_by_name_in_order():
    things = Registry("thing")
    things.register("b", Thing)
    things.register("a", "collections:OrderedDict")
    assert things.names() == ("b", "a")
    assert "a" in things and "c" not in things and len(things) == 2
    assert things.load("b") is Thing
    from collections import OrderedDict

    assert things.entry("a") == "collections:OrderedDict"  # not imported until loaded
    assert things.load("a") is OrderedDict


def test_the_same_entry_again_is_a_no_op_another_is_refused():
    things = Registry("thing")
    things.register("x", Thing)
    things.register("x", Thing)
    with pytest.raises(RegistryError, match="a thing named 'x' is already registered"):
        things.register("x", "collections:OrderedDict")
    with pytest.raises(RegistryError, match="non-empty string"):
        things.register("", Thing)


def test_an_unknown_name_lists_the_known_ones_in_one_line():
    things = Registry("thing")
    things.register("x", Thing)
    with pytest.raises(RegistryError) as caught:
        things.load("y")
    assert str(caught.value) == "unknown thing 'y'; this spikectl has x"


def test_load_target_refuses_a_string_without_an_attribute():
    with pytest.raises(RegistryError, match="module:attribute"):
        load_target("collections")

import pytest

from dbench import registry
from dbench.errors import DbenchInputError, UnknownNameError


def test_available_and_get():
    names = registry.available()
    assert {"noisy", "oidn"} <= set(names) and names == sorted(names)
    m = registry.get("noisy")
    assert m.name == "noisy" and "steady" in m.kinds and "color" in m.needs
    assert isinstance(m.defaults, dict)


def test_unknown_method_lists_valid_names():
    with pytest.raises(UnknownNameError, match="available methods: .*noisy"):
        registry.get("bogus")


def test_unknown_parameter_is_rejected():
    with pytest.raises(DbenchInputError, match="unknown parameter"):
        registry.get("noisy", radius=3)


def test_every_method_declares_valid_kinds_and_needs():
    from dbench.data import BUFFER_NAMES
    for name in registry.available():
        cls = registry.method_class(name)
        assert cls.kinds <= {"steady", "sequence", "transient"} and cls.kinds
        assert "color" in cls.needs and cls.needs <= set(BUFFER_NAMES)


def test_applies_to_explains_skips():
    m = registry.get("oidn")
    ok, why = m.applies_to("transient")
    assert not ok and "transient" in why
    ok, why = m.applies_to("steady", {"color"})
    assert not ok and "albedo" in why

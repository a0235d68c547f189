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


def test_a_parameter_of_another_kind_than_its_default_is_rejected():
    """Denoiser.__init__ (dbench.denoiser.check_like_default): a bool default takes True or
    False, an int default an integer, a float default a number that is not NaN; NumPy scalars
    of the right kind pass, and None-default parameters are the method's to check."""
    import numpy as np

    for name, value, said in (("oidn", {"clean_aux": "false"}, "expected True or False"),
                              ("oidn", {"clean_aux": 1}, "expected True or False"),
                              ("jbf", {"radius": 2.5}, "expected an integer"),
                              ("jbf", {"radius": True}, "expected an integer"),
                              ("jbf", {"sigma_depth": float("nan")}, "expected a number"),
                              ("jbf", {"sigma_depth": "0.1"}, "expected a number")):
        with pytest.raises(DbenchInputError, match=f"{next(iter(value))}: {said}"):
            registry.get(name, **value)
    registry.get("jbf", radius=np.int64(3), sigma_depth=np.float32(0.02), hit_mask=np.bool_(0),
                 sigma_position=1)  # an int where the default is a float is a number
    registry.get("accumulate", n_max=20.0)  # an integral float is an integer
    with pytest.raises(DbenchInputError, match=r"seed: expected an integer in \[0, "):
        registry.get("bmfr", seed=-1)  # it failed inside NumPy on the first frame


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


@pytest.mark.parametrize("name", [None, 5])
def test_a_method_name_that_is_no_string_is_an_unknown_name(name):
    with pytest.raises(UnknownNameError, match="method: expected a name"):
        registry.get(name)


@pytest.mark.parametrize("name, said", [
    ("x,y", "expected letters"), ("q[k=1]", "expected letters"), ("sp ace", "expected letters"),
    ("", "expected letters"), ("../up", "expected letters"), (5, "expected letters"),
    ("all", "stands for every method"), ("jbf+gate", "wrapped by ProDen's gate"),
    ("statistical-gate", "old name of statistical\\+gate")])
def test_a_name_that_could_not_be_asked_for_or_names_another_method_is_refused(name, said):
    # a comma list could not select 'x,y', 'q[k=1]' took the label of q with k=1 (one row,
    # one file for two methods), 'jbf+gate' stood in for the gated jbf: each was registered
    from dbench.denoiser import Denoiser, register

    cls = type("Odd", (Denoiser,), {"denoise": lambda self, data: data.color})
    with pytest.raises(ValueError, match=said):
        register(name)(cls)
    assert name not in registry.available()


@pytest.mark.parametrize("kinds", [{"stedy"}, "steady", set()])
def test_kinds_outside_steady_sequence_transient_are_refused(kinds):
    # a misspelt kind was registered and then skipped on every scene
    from dbench.denoiser import Denoiser, register

    cls = type("Kinds", (Denoiser,), {"kinds": kinds, "denoise": lambda self, data: data.color})
    with pytest.raises(ValueError, match="expected a non-empty set of steady, sequence"):
        register("kinds-test")(cls)
    assert "kinds-test" not in registry.available()


@pytest.mark.parametrize("default", [lambda x: x, object(), float("nan"), {"a", "b"},
                                     __import__("numpy").float32(0.5), [1, object()]])
def test_a_default_that_is_no_identity_value_is_refused(default):
    # a function's or an object's repr holds its address: a resumed sweep called every cell
    # of the method changed ('differs in params.k'); a NaN default labelled the method run
    # with its defaults 'name[k=NaN]'
    from dbench.denoiser import Denoiser, register

    cls = type("Defaults", (Denoiser,), {"defaults": {"k": default},
                                         "denoise": lambda self, data: data.color})
    with pytest.raises(ValueError, match="default 'k'=.*expected None, True/False, a Python"):
        register("defaults-test")(cls)
    assert "defaults-test" not in registry.available()


@pytest.mark.parametrize("defaults", [[("k", 1)], None])
def test_defaults_that_are_no_dict_are_refused(defaults):
    # a list of pairs was registered, then building the method was an internal error
    from dbench.denoiser import Denoiser, register

    cls = type("NoDict", (Denoiser,), {"defaults": defaults,
                                       "denoise": lambda self, data: data.color})
    with pytest.raises(ValueError, match="expected a dict of parameter names"):
        register("no-dict-test")(cls)
    assert "no-dict-test" not in registry.available()


def test_a_version_that_is_no_string_or_number_is_refused():
    # a property's repr holds its address: every resumed sweep found the method's code changed
    # ('differs in method_version') though nothing had
    from dbench.denoiser import Denoiser, register

    cls = type("Versioned", (Denoiser,), {"version": property(lambda self: "1.0"),
                                          "denoise": lambda self, data: data.color})
    with pytest.raises(ValueError, match="version <property .*expected a class attribute"):
        register("versioned-test")(cls)
    assert "versioned-test" not in registry.available()

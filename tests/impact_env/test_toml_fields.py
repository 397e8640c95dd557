"""Reading a task file (impact_env/toml_fields.py), the same for both world families: the source (a shipped
name or a path), the TOML, the header fields and the prefix that names the file in every error."""

from __future__ import annotations

import dataclasses
from importlib.resources import files

import pytest

from impact_env.errors import ScenarioError
from impact_env.tether.station import load_station, station_from_dict
from impact_env.toml_fields import Fields, check, load_toml, read_header
from impact_env.transport.scenario import load_scenario, scenario_from_dict

# kind, loader, from_dict, a shipped name, its resource package, a typo and the name it suggests
FAMILIES = [
    ("scenario", load_scenario, scenario_from_dict, "corridor", "impact_env.transport.scenarios", "corrid",
     "corridor"),
    ("station", load_station, station_from_dict, "T", "impact_env.tether.stations", "alcov", "alcove"),
]
IDS = [kind for kind, *_ in FAMILIES]


@pytest.mark.parametrize("kind,load,_from_dict,name,package,typo,meant", FAMILIES, ids=IDS)
def test_a_shipped_name_and_its_file_by_path_load_the_same(kind, load, _from_dict, name, package, typo, meant,
                                                           tmp_path):
    path = tmp_path / "copy.toml"
    path.write_text(files(package).joinpath(f"{name}.toml").read_text())
    by_path, by_name = load(path), load(name)
    assert by_path.source == str(path) and by_name.source == name
    assert dataclasses.replace(by_path, source=name) == by_name


@pytest.mark.parametrize("kind,load,_from_dict,name,package,typo,meant", FAMILIES, ids=IDS)
def test_unknown_name_missing_file_and_bad_files(kind, load, _from_dict, name, package, typo, meant, tmp_path):
    with pytest.raises(ScenarioError, match=rf"unknown {kind} '{typo}' \(did you mean '{meant}'\?\); shipped {kind}s: "
                                            rf".*{name}.* \(or pass a path to a \.toml file\)"):
        load(typo)
    with pytest.raises(ScenarioError, match=rf"{kind} file '.*nope.toml' does not exist"):
        load(tmp_path / "nope.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("name = [")
    with pytest.raises(ScenarioError, match=r"bad\.toml: not valid TOML"):
        load(bad)
    bad.write_bytes(b"name = 'caf\xe9'\n")
    with pytest.raises(ScenarioError, match=r"bad\.toml: not UTF-8 text \(byte 0xe9 at line 1"):
        load(bad)
    with pytest.raises(ScenarioError, match=rf"a {kind} is a shipped name or a path to a \.toml file, got int"):
        load(3)
    with pytest.raises(ScenarioError, match=rf"is neither a shipped {kind} nor a readable path"):
        load("x" * 5000)


def test_a_station_given_to_the_scenario_loader_is_named_as_one():
    with pytest.raises(ScenarioError, match="'L' is a tether station, not an impact scenario: load it with "
                                            r"impact_env\.load_station"):
        load_scenario("L")


@pytest.mark.parametrize("kind,_load,from_dict,name,package,typo,meant", FAMILIES, ids=IDS)
def test_errors_name_the_source_once(kind, _load, from_dict, name, package, typo, meant):
    with pytest.raises(ScenarioError) as info:
        from_dict({"name": "x", "restitution": 1.5}, source="mine.toml")
    assert str(info.value) == "mine.toml: restitution must be in [0, 1], got 1.5"
    with pytest.raises(ScenarioError) as info:
        from_dict({"name": "x", "restitution": 0.5, "tf_s": 0}, source="mine.toml")
    assert str(info.value) == "mine.toml: tf_s must be > 0, got 0.0"


def test_header_defaults_and_checks():
    top = Fields({"name": "lab", "restitution": 0.5, "tf_s": 20}, "")
    header = read_header(top, default_period_s=0.25)
    assert (header.name, header.description, header.restitution, header.tf_s, header.control_period_s,
            header.substeps) == ("lab", "", 0.5, 20.0, 0.25, 10)
    with pytest.raises(ScenarioError, match="substeps must be >= 1, got 0"):
        read_header(Fields({"name": "lab", "restitution": 0.5, "tf_s": 20, "substeps": 0}, ""), 0.1)
    with pytest.raises(ScenarioError, match="name is required"):
        read_header(Fields({}, ""), 0.1)


def test_fields_report_the_first_unknown_key_and_what_is_allowed():
    f = Fields({"a": 1, "zz": 2, "b": 3}, "planner")
    assert f.get("a", kind="int") == 1 and f.get("c", None) is None
    with pytest.raises(ScenarioError, match=r"planner\.b: unknown key \(allowed here: a, c\)"):
        f.finish()


@pytest.mark.parametrize("value,kind,message", [
    (True, "int", "x must be an integer, got True"),
    (10 ** 400, "float", "x must be a finite number, got 1000"),
    ([1, 2, 3], "vec2", "x must be a list of 2 numbers [x, y], got [1, 2, 3]"),
    ([0, 1, 1, 0], "box", "x must have xmin < xmax and ymin < ymax, got [0.0, 1.0, 1.0, 0.0]"),
    ("a b", "name", "x must be a name made of letters, digits and _, got 'a b'"),
])
def test_check_names_the_field_and_the_value(value, kind, message):
    with pytest.raises(ScenarioError) as info:
        check(value, kind, "x")
    assert str(info.value).startswith(message)


def test_load_toml_returns_the_document_and_its_source():
    data, source = load_toml("corridor", "scenario")
    assert source == "corridor" and data["name"] == "corridor" and "robots" in data

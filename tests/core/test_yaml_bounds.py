"""One bounded YAML loader for every file the package reads (config.BoundedLoader; issue 32 item 5): an alias
tree (9 levels of 9 aliases, 9^9 nodes once expanded) is refused while composing, naming the file and the line,
wherever it sits (a known key included: a scene's name, a target's dictionary, a robot's kind, a TransformPairs
file); a recursive alias is refused; ordinary anchors, aliases and merge keys still load as PyYAML loads them."""

from __future__ import annotations

import re

import pytest
import yaml

from vision_calib.cli import main
from vision_calib.config import MAX_YAML_ALIAS_NODES, MAX_YAML_ALIASES, safe_load
from vision_calib.errors import DataError
from vision_calib.shipped import data_dir


def alias_tree(levels: int = 9, width: int = 9) -> str:
    """A flow list holding &a0 [9 strings], &a1 [9 x *a0], ..., &a{levels-1}: width^levels strings expanded."""
    parts = ["&a0 [" + ", ".join(['"lol"'] * width) + "]"]
    parts += [f"&a{k} [" + ", ".join([f"*a{k - 1}"] * width) + "]" for k in range(1, levels)]
    return "[" + ", ".join(parts) + "]"


def with_tree(text: str, key: str) -> str:
    """``text`` with the value of its first top-level ``key:`` replaced by :func:`alias_tree`."""
    new, n = re.subn(rf"^{key}:.*$", lambda m: f"{key}: {alias_tree()}", text, count=1, flags=re.M)
    assert n == 1
    return new


def test_ordinary_anchors_and_merge_keys_load_as_pyyaml():
    text = ("base: &cam {width: 1024, height: 768}\nleft: *cam\nright: {<<: *cam, height: 480}\n"
            "list: &l [1, 2, 3]\nagain: [*l, *l]\n")
    assert safe_load(text) == yaml.safe_load(text)


def test_alias_tree_and_recursion_refused_with_the_line():
    with pytest.raises(yaml.YAMLError, match=r"aliases expand beyond the limit .*an alias tree") as exc:
        safe_load("a: 1\nname: " + alias_tree() + "\n")
    assert exc.value.problem_mark.line == 1  # the second line: where the expansion passes the limit
    with pytest.raises(yaml.YAMLError, match=r"the alias \*r is inside the node &r it repeats"):
        safe_load("x: &r [1, *r]\n")
    # many small aliases: the alias count bounds them too
    many = "a: &a 1\nb: [" + ", ".join(["*a"] * (MAX_YAML_ALIASES + 1)) + "]\n"
    with pytest.raises(yaml.YAMLError, match=rf"{MAX_YAML_ALIASES + 1} aliases"):
        safe_load(many)
    # just below both limits: loaded
    below = "a: &a [" + ", ".join(["1"] * 99) + "]\nb: [" + ", ".join(["*a"] * (MAX_YAML_ALIAS_NODES // 100)) + "]\n"
    assert len(safe_load(below)["b"]) == MAX_YAML_ALIAS_NODES // 100


@pytest.mark.parametrize("what, key", [("scene", "name"), ("target", "dictionary"), ("robot", "kind")])
def test_alias_tree_in_a_known_key_is_a_named_error(tmp_path, capsys, what, key):
    """identifiability on a scene whose name, target dictionary or robot kind holds the tree: exit 2, the file
    named (the same tree took 30-60 s and 2.5-3.1 GB before this loader)."""
    scenes, targets = data_dir() / "scenes", data_dir() / "targets"
    src = scenes / ("h4_vision.yaml" if what == "robot" else "rx90_eye_in_hand.yaml")
    text = re.sub(r"^robot: robots/", f"robot: {scenes}/robots/", src.read_text(), flags=re.M)
    text = text.replace("../targets/", f"{targets}/")
    bad = tmp_path / f"{what}.yaml"
    if what == "scene":
        text = with_tree(text, key)
    elif what == "target":
        bad.write_text(with_tree((targets / "charuco_a5.yaml").read_text(), key))
        text = text.replace(f"{targets}/charuco_a5.yaml", str(bad))
    else:
        bad.write_text(with_tree((scenes / "robots" / "h4.yaml").read_text(), key))
        text = text.replace(f"{scenes}/robots/h4.yaml", str(bad))
    scene = tmp_path / "scene.yaml"
    scene.write_text(text)
    bad = scene if what == "scene" else bad
    assert main(["identifiability", str(scene), "--allow-path", str(data_dir())]) == 2
    err = capsys.readouterr().err
    assert f"{bad}: invalid YAML (aliases expand beyond the limit" in err, err


def test_transform_pairs_alias_tree_is_a_data_error(tmp_path):
    from vision_calib.io.transform_pairs import read_transform_pairs

    p = tmp_path / "pairs.yml"
    p.write_text("%YAML:1.0\n---\nframeCount: " + alias_tree() + "\n")
    with pytest.raises(DataError, match=r"pairs.yml: line 3: not a readable YAML file \(aliases expand beyond"):
        read_transform_pairs(p)


def test_a_text_parsed_again_gives_its_values_unshared():
    """safe_load keeps the values of the texts it parsed: the same text again gives equal values, never the same
    objects (a caller changing its copy changes no other's)."""
    text = "robot:\n  links: [{a: 1.5, d: 0.2}, {a: 0.0, d: -0.1}]\n  name: arm\n"
    a = safe_load(text)
    a["robot"]["links"][0]["a"] = 99.0
    b, c = safe_load(text), safe_load(text)
    assert b == c == {"robot": {"links": [{"a": 1.5, "d": 0.2}, {"a": 0.0, "d": -0.1}], "name": "arm"}}
    assert b is not c and b["robot"]["links"] is not c["robot"]["links"]

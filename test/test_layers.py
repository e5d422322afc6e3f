"""The package's layers (ARCHITECTURE.md): imports run only downward, and only the ROS layer
touches ROS. Read from the source with ast, so an import inside a function counts too."""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "tof_calib_ros"
NAME = PACKAGE.name
# Each layer may import the layers of a lower rank and itself; layers of one rank are peers,
# which do not import each other. "api" is the package's own __init__ (the public API).
RANK = {"core": 0, "api": 1, "collect": 2, "files": 3, "sim": 4, "settings": 4, "offline": 5, "ros": 5}
ROS_PACKAGES = {"rclpy", "rcl_interfaces", "sensor_msgs", "std_srvs", "std_msgs", "diagnostic_msgs",
                "builtin_interfaces", "rosidl_runtime_py", "rosgraph_msgs"}


def layer_of(module: str) -> str:
    """'tof_calib_ros.collect.replay' -> 'collect'; the package itself -> 'api'."""
    parts = module.split(".")
    return "api" if len(parts) == 1 else parts[1]


def module_name(path: Path) -> str:
    parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imports(source: str, module: str, is_package: bool) -> list[tuple[int, str]]:
    """(line, absolute module) for every import in ``source``; ``from X import name`` counts as
    X.name when that is one of our modules (``from .. import sim``)."""
    package = module if is_package else module.rpartition(".")[0]
    ours = {module_name(p) for p in PACKAGE.rglob("*.py")}
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module
            names = [f"{target}.{a.name}" for a in node.names]
            found += [(node.lineno, n if n in ours else target) for n in names]
    return found


def violations(source: str, module: str, is_package: bool = False) -> list[str]:
    """What ``source``, as ``module``, imports against the layering."""
    own = layer_of(module)
    out = []
    for line, target in imports(source, module, is_package):
        top = target.split(".")[0]
        if top in ROS_PACKAGES and own != "ros":
            out.append(f"{module}:{line} imports {target}: ROS outside the ros layer")
        if top != NAME:
            continue
        other = layer_of(target)
        if other != own and RANK[other] >= RANK[own]:
            out.append(f"{module}:{line}: {own} may not import {target} ({other})")
    return out


def package_files() -> list[Path]:
    return sorted(PACKAGE.rglob("*.py"))


def test_every_module_is_in_a_layer():
    assert {layer_of(module_name(p)) for p in package_files()} <= set(RANK)
    for p in PACKAGE.iterdir():
        if p.is_dir() and (p / "__init__.py").exists():
            doc = ast.get_docstring(ast.parse((p / "__init__.py").read_text()))
            assert doc and "import" in doc, f"{p.name}/__init__.py must say what the layer holds and may import"


@pytest.mark.parametrize("path", package_files(), ids=lambda p: str(p.relative_to(PACKAGE)))
def test_imports_run_only_downward_and_ros_stays_in_its_layer(path):
    assert violations(path.read_text(), module_name(path), path.name == "__init__.py") == []


@pytest.mark.parametrize("module, source, expected", [
    ("tof_calib_ros.core.bundle", "from ..collect.replay import Replay", "may not import tof_calib_ros.collect.replay"),
    ("tof_calib_ros.core.bundle", "from .. import Board", "may not import tof_calib_ros (api)"),
    ("tof_calib_ros.collect.replay", "def f():\n    from ..files import bag_io", "may not import tof_calib_ros.files"),
    ("tof_calib_ros.files.bag_io", "import tof_calib_ros.ros.node", "may not import tof_calib_ros.ros.node"),
    ("tof_calib_ros.offline.cli", "from ..ros.processes import wait_until", "may not import tof_calib_ros.ros"),
    ("tof_calib_ros.sim.recording", "from ..settings import SETTINGS", "may not import tof_calib_ros.settings"),
    ("tof_calib_ros.collect.replay", "from .. import Board, sim", "may not import tof_calib_ros.sim"),
    ("tof_calib_ros.offline.cli", "import rclpy", "ROS outside the ros layer"),
    ("tof_calib_ros.settings", "from sensor_msgs.msg import Image", "ROS outside the ros layer"),
])
def test_the_check_finds_an_upward_import(module, source, expected):
    found = violations(source, module)
    assert len(found) == 1 and expected in found[0], found


def test_the_check_lets_downward_imports_pass():
    assert violations("from ..core.board import Board\nfrom ..collect.replay import Replay\nfrom .. import sim\n"
                      "from ..settings import SETTINGS\nimport rclpy", "tof_calib_ros.ros.node") == []
    assert violations("from .. import sim\nfrom ..files.bag_io import BagWriter", "tof_calib_ros.sim.recording") == []

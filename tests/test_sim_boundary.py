"""The simulated bench is a set of devices and nothing more: production code
(everything under appliance/ except sim/ and commands/) never imports it
(tests/test_import_graph.py checks that with the other room rules), and never
asks a device or a factory whether it happens to have a simulator-only method.
What a bench offers is in hw/base.py's interfaces."""

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "appliance"
ALLOWED = ("sim", "commands")
SIMULATOR_ONLY = {
    "note_move_finished",
    "disk_free_mb",
    "usb",
    "extra_params",
    "calibration_target",
    "surface",
}


def production_modules():
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(PACKAGE)
        if rel.parts[0] not in ALLOWED:
            yield rel, ast.parse(path.read_text(), str(path))


def test_no_production_module_probes_for_simulator_only_methods():
    probes = []
    for rel, tree in production_modules():
        for node in ast.walk(tree):
            if (
                isinstance(node, ast.Call)
                and isinstance(node.func, ast.Name)
                and node.func.id in ("getattr", "hasattr")
                and len(node.args) >= 2
                and isinstance(node.args[1], ast.Constant)
                and node.args[1].value in SIMULATOR_ONLY
            ):
                probes.append(f"{rel}:{node.lineno}: {node.func.id}(..., {node.args[1].value!r})")
    assert probes == []


def test_the_simulator_only_names_are_parts_of_the_interfaces():
    from appliance.hw.base import BenchFactory, Stage
    from appliance.hw.devices import HardwareBench

    bench = HardwareBench()
    assert isinstance(bench, BenchFactory) and bench.extra_params == () and bench.calibration_target == {}
    assert bench.disk_free_mb(PACKAGE) > 0
    assert "travel_mm" in Stage.__abstractmethods__


def test_truth_files_are_no_business_of_production_code():
    mentions = [str(rel) for rel, _ in production_modules() if "truth.json" in (PACKAGE / rel).read_text()]
    assert mentions == []

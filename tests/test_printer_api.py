"""The host-side printer API (driver/printer.py) and `wideprint printer ...`: on the
in-process emulator, and on a standalone emulator over a real pseudo-terminal and TCP
(the command keeps its state across invocations there, as a real printer does)."""

import json
import subprocess
import sys

import pytest

from support.server import start_emulator
from wideprint.app.devices import close_device, open_device
from wideprint.device_sim.faults import Faults
from wideprint.driver import protocol as P
from wideprint.driver.printer import Printer, PrinterFault


def cli(*args, timeout=60):
    return subprocess.run([sys.executable, "-m", "wideprint.app.cli", *args],
                          capture_output=True, text=True, timeout=timeout)


@pytest.fixture
def printer(profile):
    dev = open_device("emulator", profile, Faults(paper_width_mm=1200))
    yield Printer(dev)
    close_device(dev)


def test_ready_brings_a_cold_printer_to_printing(printer):
    info = printer.connect()
    assert info["heads"] == 8 and info["serial"].startswith("WP3400")
    st = printer.status()
    assert not st.flags & (P.FLAG_HOMED | P.FLAG_HEADS_CONFIGURED)
    steps = []
    st = printer.ready(on_step=steps.append)
    assert steps == ["loading head configuration", "homing", "measuring paper"]
    want = P.FLAG_ENABLED | P.FLAG_HOMED | P.FLAG_HEADS_CONFIGURED | P.FLAG_PAPER_MEASURED
    assert st.flags & want == want and st.fault == 0
    assert printer.ready(on_step=steps.append) and len(steps) == 3     # nothing left to do
    paper = printer.paper()
    assert paper.present and abs(paper.width_mm - 1200) < 0.2
    heads = printer.heads()
    assert [h.name for h in heads] == [h.name for h in printer.profile.heads]
    assert all(h.configured and not h.overtemp for h in heads)
    assert printer.head_temperatures() == tuple(h.temperature_c for h in heads)
    assert printer.fifo_levels() == (0,) * 8


def test_feed_moves_the_paper_by_millimetres(printer):
    printer.ready()
    before = printer.status().paper_steps
    steps = printer.feed(25.4)
    assert steps == round(25400 / printer.profile.feed_um_per_step)
    assert printer.status().paper_steps - before == steps
    printer.feed(-10)
    assert printer.status().paper_steps - before == steps - round(10000 / printer.profile.feed_um_per_step)


def test_park_and_home(printer):
    printer.ready()
    printer.park()
    park = printer.status().carriage
    assert park == printer.profile.carriage.park_counts
    printer.home()
    assert printer.status().carriage == printer.profile.carriage.home_counts


def test_a_latched_fault_is_named_and_cleared(profile):
    dev = open_device("emulator", profile, Faults(paper_length_mm=5))
    try:
        printer = Printer(dev)
        printer.ready()
        with pytest.raises(PrinterFault, match="feeding paper: paper out") as e:
            printer.feed(20)
        assert e.value.fault == P.Fault.PAPER_OUT
        # any motion command now names the fault rather than a bare refusal
        with pytest.raises(PrinterFault, match="PARK refused: paper out"):
            printer.park()
        assert printer.fault_text() == "paper out"
        assert printer.clear_fault() == P.Fault.PAPER_OUT
        assert printer.fault_text() == "" and printer.clear_fault() == 0
    finally:
        close_device(dev)


def test_printer_commands_on_the_in_process_emulator():
    r = cli("printer", "status", "--json")
    assert r.returncode == 0, r.stderr
    st = json.loads(r.stdout)
    assert st["enabled"] is False and st["fault"] is None and len(st["heads"]) == 8
    r = cli("printer", "measure", "--inject", "paper-width-mm=500")
    assert r.returncode == 0 and "paper: 500.0 mm wide" in r.stdout, r.stdout + r.stderr
    r = cli("printer", "feed", "100", "--inject", "paper-length-mm=10")
    assert r.returncode == 1 and "paper out" in r.stderr
    assert cli("printer", "feed").returncode == 2                     # feed needs a length
    assert cli("printer", "status", "--device", "serial=/nonexistent/tty,data=tcp://127.0.0.1:1"
               ).returncode == 3


def test_printer_commands_on_a_real_link_keep_the_printer_state(tmp_path):
    proc, spec = start_emulator(tmp_path, "--inject", "paper-width-mm=900")
    try:
        def status():
            r = cli("printer", "status", "--json", "--device", spec)
            assert r.returncode == 0, r.stderr
            return json.loads(r.stdout)
        assert status()["homed"] is False
        r = cli("printer", "measure", "--device", spec)
        assert r.returncode == 0, r.stderr
        width = float(r.stdout.split("paper: ")[1].split(" mm")[0])
        assert abs(width - 900) < 0.15                  # the sensor reads whole encoder counts
        st = status()
        assert st["homed"] and st["paper_measured"] and st["paper"]["width_mm"] == width
        r = cli("printer", "feed", "12.5", "--device", spec)
        assert r.returncode == 0 and "fed 12.5" in r.stdout, r.stderr
        steps = status()["paper_steps"]
        assert steps == round(12500 / 23.56194490192345)
        assert cli("printer", "park", "--device", spec).returncode == 0
        assert status()["carriage_mm"] == pytest.approx(25.4)
        assert cli("printer", "clear-fault", "--device", spec).stdout.strip() == "no fault was latched"
    finally:
        proc.terminate()
        out, err = proc.communicate(timeout=10)
    assert "Traceback" not in err, err

"""VCD waveforms of the head interface, the encoder and the feed stepper (opens in GTKWave).

The emulator is event-driven and does not clock these signals; for a chosen window it
regenerates them from what it decided (fire times, words, configuration digits) with the
timing of docs/protocol.md section 4:
- configuration: DI0..DI3 one hex digit per DSTB rising edge at 500 kHz, DATA_nCONFIG low
  during the load and high one DSTB period after the 1,020th digit;
- a fire: the FPGA's 7.5 MHz read clock shifts the 128 bits out on DI3 (nozzle 127 first,
  one bit per DSTB rising edge), then CYCLESTB1 strobes phases A, B, C (C, B, A in reverse)
  a third of the minimum fire period apart, 10 µs high each, with SAMPLECLK at 1 MHz
  (ten periods inside each strobe: the head needs at least two);
- encoder A/B in quadrature from the carriage position; the L297 phase outputs per step.
"""

from __future__ import annotations

import io
import string

import numpy as np

DSTB_PRINT_HZ = 7_500_000
CYCLESTB_HIGH_NS = 10_000
SAMPLECLK_HZ = 1_000_000


class Vcd:
    """Collects (time ns, signal, value) changes and writes a VCD file."""

    def __init__(self, timescale: str = "1ns"):
        self.timescale = timescale
        self.signals: dict[str, tuple[str, int, str]] = {}     # name -> (id, width, scope)
        self.changes: list[tuple[int, str, int]] = []

    def signal(self, name: str, width: int = 1, scope: str = "wideprint") -> str:
        if name not in self.signals:
            n = len(self.signals)
            chars = string.ascii_letters + string.digits + "!#$%&'()*+,-./:;<=>?@[]^_`{|}~"
            ident = chars[n % len(chars)] + (chars[n // len(chars)] if n >= len(chars) else "")
            self.signals[name] = (ident, width, scope)
        return name

    def set(self, t_ns: int, name: str, value: int) -> None:
        self.changes.append((int(t_ns), name, int(value)))

    def pulse(self, t_ns: int, name: str, high_ns: int) -> None:
        self.set(t_ns, name, 1)
        self.set(t_ns + high_ns, name, 0)

    def write(self, path) -> None:
        out = io.StringIO()
        out.write("$date wideprint emulator $end\n$version wideprint device_sim $end\n")
        out.write(f"$timescale {self.timescale} $end\n")
        scopes: dict[str, list[str]] = {}
        for name, (_, _, scope) in self.signals.items():
            scopes.setdefault(scope, []).append(name)
        for scope, names in scopes.items():
            out.write(f"$scope module {scope} $end\n")
            for name in names:
                ident, width, _ = self.signals[name]
                out.write(f"$var wire {width} {ident} {name} $end\n")
            out.write("$upscope $end\n")
        out.write("$enddefinitions $end\n")
        changes = sorted(self.changes, key=lambda c: c[0])
        t_prev = None
        last: dict[str, int] = {}
        out.write("$dumpvars\n")
        for name, (ident, width, _) in self.signals.items():
            out.write(("0" if width == 1 else "b0 ") + ident + "\n")
            last[name] = 0
        out.write("$end\n")
        for t, name, value in changes:
            if last.get(name) == value:
                continue
            if t != t_prev:
                out.write(f"#{t}\n")
                t_prev = t
            ident, width, _ = self.signals[name]
            out.write((f"{value & 1}{ident}\n") if width == 1 else f"b{value:b} {ident}\n")
            last[name] = value
        with open(path, "w") as fh:
            fh.write(out.getvalue())


def head_signals(vcd: Vcd, head: str) -> dict[str, str]:
    scope = f"head_{head}"
    names = {s: vcd.signal(f"{head}_{s}", 1, scope) for s in
             ("DATA_nCONFIG", "DI0", "DI1", "DI2", "DI3", "DSTB", "CYCLESTB1", "DIR", "SAMPLECLK")}
    return names


def add_config_load(vcd: Vcd, head: str, digits: list[int], dstb_rise_ns: np.ndarray,
                    nconfig_rise_ns: int) -> None:
    s = head_signals(vcd, head)
    period = int(dstb_rise_ns[1] - dstb_rise_ns[0]) if len(dstb_rise_ns) > 1 else 2000
    t0 = int(dstb_rise_ns[0]) - period // 2
    vcd.set(t0, s["DATA_nCONFIG"], 0)
    for d, rise in zip(digits, dstb_rise_ns):
        rise = int(rise)
        for bit in range(4):                      # DI0 = LSB
            vcd.set(rise - period // 2, s[f"DI{bit}"], (d >> bit) & 1)
        vcd.pulse(rise, s["DSTB"], period // 2)
    vcd.set(nconfig_rise_ns, s["DATA_nCONFIG"], 1)
    for bit in range(4):
        vcd.set(nconfig_rise_ns, s[f"DI{bit}"], 0)


def add_fire(vcd: Vcd, head: str, t_ns: int, serial_bits: np.ndarray, forward: bool,
             min_fire_period_ns: int) -> None:
    """One fire: 128 DSTB clocks of DI3 carrying `serial_bits` in the order they are sent
    (head.serial_order), then the three strobes."""
    s = head_signals(vcd, head)
    vcd.set(t_ns, s["DIR"], 1 if forward else 0)
    vcd.set(t_ns, s["DATA_nCONFIG"], 1)
    half = 1_000_000_000 // DSTB_PRINT_HZ // 2
    t = t_ns
    for bit in serial_bits:
        vcd.set(t, s["DI3"], int(bit))
        vcd.pulse(t + half, s["DSTB"], half)
        t += 2 * half
    vcd.set(t, s["DI3"], 0)
    gap = min_fire_period_ns // 3
    clk_half = 1_000_000_000 // SAMPLECLK_HZ // 2
    for phase in range(3):
        start = t + phase * gap
        vcd.pulse(start, s["CYCLESTB1"], CYCLESTB_HIGH_NS)
        for c in range(start, start + CYCLESTB_HIGH_NS, 2 * clk_half):
            vcd.pulse(c, s["SAMPLECLK"], clk_half)


def add_encoder(vcd: Vcd, counts: np.ndarray, times_ns: np.ndarray) -> None:
    """Quadrature A/B for the carriage passing these counts at these times (x4 decoding,
    the Gray sequence (A, B) = 10, 11, 01, 00 for counts 0, 1, 2, 3 mod 4), phased so the
    edges docs/protocol.md names are the ones that fire: count 4n is entered forward on a
    rising edge of A (150 dpi), count 2n on an edge of A (300 dpi: both edges), every
    count on an edge of A or B (600 dpi)."""
    a, b = vcd.signal("encoder_A", 1, "encoder"), vcd.signal("encoder_B", 1, "encoder")
    cnt = vcd.signal("qep_count", 32, "encoder")
    gray = ((1, 0), (1, 1), (0, 1), (0, 0))
    for c, t in zip(counts, times_ns):
        va, vb = gray[int(c) % 4]
        vcd.set(int(t), a, va)
        vcd.set(int(t), b, vb)
        vcd.set(int(t), cnt, int(c) & 0xFFFFFFFF)


def add_stepper(vcd: Vcd, step_times_ns: np.ndarray, phases: np.ndarray) -> None:
    """L297 outputs A, B, C, D per step (phases: (steps, 4) of 0/1)."""
    names = [vcd.signal(f"L297_{p}", 1, "feed") for p in "ABCD"]
    for t, ph in zip(step_times_ns, phases):
        for name, v in zip(names, ph):
            vcd.set(int(t), name, int(v))

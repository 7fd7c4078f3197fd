"""Xaar XJ128 head and the carriage board's CPLD (docs/protocol.md section 4).

The head holds a 128-bit shift register loaded nozzle 127 first on DI3, fires it in three
phases (A: nozzles 3n+1, B: 3n+2, C: 3n+3; reverse order when DIR = 0) and refuses to
print until its 1020-digit configuration has been clocked in on DI0..DI3 since power-up.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

CONFIG_DIGITS = 1020
CONFIG_DSTB_HZ = 500_000
NOZZLES = 128


def serial_order(bits: np.ndarray) -> np.ndarray:
    """The DI3 bit sequence of one fire: nozzle 127 first, so that after 128 DSTB edges the
    first bit sent sits at nozzle 127 (docs/protocol.md 4.3)."""
    return bits[::-1]


@dataclass
class ConfigTrace:
    """What a logic analyser on the head connector sees during the configuration load."""
    digits: list[int]
    dstb_rise_ns: np.ndarray          # rising edge times of DSTB
    data_nconfig_rise_ns: int         # DATA_nCONFIG goes high (print mode) here


@dataclass
class Head:
    index: int
    name: str
    configured: bool = False
    temperature_c: float = 35.0
    overtemp_c: float = 55.0
    piezo_v: float = 40.0
    dead: set = field(default_factory=set)      # injected dead nozzles: they never drop
    fires: int = 0

    def load_config(self, digits: list[int], t0_ns: int = 0) -> ConfigTrace:
        if len(digits) != CONFIG_DIGITS or any(not 0 <= d <= 15 for d in digits):
            self.configured = False
            raise ValueError(f"head configuration must be {CONFIG_DIGITS} hex digits")
        period = 1_000_000_000 // CONFIG_DSTB_HZ
        rises = t0_ns + period // 2 + period * np.arange(CONFIG_DIGITS, dtype=np.int64)
        self.configured = True
        return ConfigTrace(list(digits), rises, int(rises[-1] + period))

    @property
    def overtemp(self) -> bool:
        return self.temperature_c > self.overtemp_c

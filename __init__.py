"""wideprint: RIP and driver for a 3.4 m CMYK solvent inkjet printer (8 x Xaar XJ128)."""

__version__ = "0.2.0"

"""fivebar host program: drawing → checked joint targets → firmware over serial."""

__version__ = "0.1.0"

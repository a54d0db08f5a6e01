"""fivebar's own firmware: the serial link, streaming, G6 packing and what follows a fault."""

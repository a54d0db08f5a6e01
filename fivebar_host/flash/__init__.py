"""Putting the fivebar firmware on a board: `fivebar flash`.

hexfile.py (Intel HEX → image), stk500.py (the Arduino bootloaders' protocol), boards.py
(USB ids: which boards can be flashed), failures.py (each failure as its cause and fix),
image.py (which hex: given, built from source, or packaged), flasher.py (the steps)."""

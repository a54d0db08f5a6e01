"""The lettering corpus of the text goals (tests and `benchmarks/text.py`): what a plotter
letters — names, labels, addresses, dates, clock digits, prices — and every printable ASCII
character, with punctuation; plus non-ASCII Latin strings for the fonts that have those
letters (Relief SingleLine: the Hershey fonts have ASCII only, in vpype as here)."""

from __future__ import annotations

import string

LABELS = [
    "The quick brown fox jumps over the lazy dog.",
    "Sphinx of black quartz, judge my vow!",
    "PACK MY BOX WITH FIVE DOZEN LIQUOR JUGS",
    "Happy Birthday, Ada!",
    "With love from all of us x",
    "Dr. Grace O'Neil & Co.",
    "221B Baker Street, London NW1 6XE",
    "1600 Pennsylvania Ave NW, Washington, DC 20500",
    "P.O. Box 42 - Springfield, IL 62704",
    "12:45", "09:30 am", "23:59:59", "Mon 1 Jan 2024",
    "$19.99 / 50% off!", "#1 best seller (limited edition)",
    "a+b=c; x*y^2 ~ z", "{[(<>)]}", "back\\slash | pipe / slash",
    '"double" and \'single\' quotes', "`tick` and _under_score_",
    "email: someone@example.org", "https://example.com/path?q=1&r=2",
    "Jar #7 - Strawberry Jam (2024)", "Table 12 - Seats 1-8",
    "Fragile! Handle with care.", "Keep dry ~ this side up ^",
    "E = mc^2", "3.14159 26535 89793", "0123456789", "Volume: 750 ml, 13.5% vol.",
    "No. 5", "Q&A", "A-Z a-z 0-9", "Mississippi", "Illinois Jill",
    "WAVE AVATAR TYPO", "Hamburgefonstiv", "minimum", "ruler: |----|----|",
    "Name: ____________", "To: Mum & Dad", "Merry Christmas!", "Thank you :)",
]
PRINTABLE = string.digits + string.ascii_letters + string.punctuation + " "
#: Every printable ASCII character, in overlapping windows of 12.
WINDOWS = [PRINTABLE[i:i + 12] for i in range(0, len(PRINTABLE) - 11, 1)]
ASCII = LABELS + WINDOWS
#: Non-ASCII Latin (Relief SingleLine has Latin-1 and Latin Extended-A).
LATIN = [
    "Café Müller — Straße 5", "Ça va? Très bien, merci.", "Señor Muñoz, año 2024",
    "Łódź, Kraków, Gdańsk", "Åsa Ørsted, Ærø", "Zürich · Genève · Köln",
    "naïve façade, coöperate", "Dvořák & Janáček", "İstanbul, Şişli", "Ÿ ÿ œ Œ",
]


def corpus() -> list[str]:
    """The ASCII corpus (≥ 100 strings)."""
    return list(ASCII)

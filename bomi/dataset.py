"""Where the published P1 recordings live: env var BOMI_DATA_DIR, else ../shared/data beside the checkout."""
from __future__ import annotations

import os
from pathlib import Path

DATA_DIR_ENV = "BOMI_DATA_DIR"
_DEFAULT = Path(__file__).resolve().parent.parent.parent / "shared" / "data" / "flexible_bomi_p1_5days"


def data_dir() -> Path:
    """Directory holding dayN_testp.mat (participant P1, days 1..5)."""
    return Path(os.environ.get(DATA_DIR_ENV, _DEFAULT))

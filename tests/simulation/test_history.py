"""The history CSV (modelgen.simulation.history): a write that fails names the file."""

import errno
import os
from pathlib import Path

import pytest

from modelgen.simulation.history import CsvHistory

FULL = Path("/dev/full")  # every write to it fails with ENOSPC, as a full disk does


@pytest.mark.skipif(not (FULL.exists() and os.access(FULL, os.W_OK)), reason="no writable /dev/full here")
def test_a_full_disk_names_the_history_file():
    """Issue 28: "No space left on device" named no file (the buffered write's flush raises without a name)."""
    history = CsvHistory(FULL, ["bias"])
    with pytest.raises(OSError) as raised:
        history.write(None, 0, 0)  # no rows: only the header's flush, which fails
    assert raised.value.errno == errno.ENOSPC and raised.value.filename == str(FULL)
    with pytest.raises(OSError) as raised:
        history.close()
    assert raised.value.errno == errno.ENOSPC and raised.value.filename == str(FULL)

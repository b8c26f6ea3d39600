"""Commands run with file permissions enforced, also as root (CI runs as root): without
CAP_DAC_OVERRIDE and CAP_DAC_READ_SEARCH root gets no exemption from a file's mode bits,
so an unreadable file or a read-only folder behaves as it does for any user."""
import os
import shutil

import pytest


def permissions_enforced(cmd: list) -> list:
    if os.geteuid() != 0:
        return cmd
    setpriv = shutil.which("setpriv")   # util-linux: on every Debian and Ubuntu system
    if setpriv is None:
        pytest.fail("running as root needs setpriv (util-linux) to test file permissions")
    return [setpriv, "--bounding-set=-dac_override,-dac_read_search", *cmd]

"""viser servers for the view: on loopback ports behind the API's relay."""

from __future__ import annotations

import contextlib
import io

import viser


def quiet_viser_server(**kwargs) -> viser.ViserServer:
    """A viser server without viser's banner: users open the API's port, never this one."""
    with contextlib.redirect_stdout(io.StringIO()):  # viser 1.1 prints the banner even with verbose=False
        return viser.ViserServer(verbose=False, **kwargs)

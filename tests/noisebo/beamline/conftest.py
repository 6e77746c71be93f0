"""Channel Access on loopback only, set before any CA client or server starts in this process or
its children, so nothing leaves the machine; and a server port of this process's own, so IOCs
that other test processes run at the same time never answer this one's searches."""

import os

from tests.noisebo.beamline.ports import free_port


os.environ.update(
    {
        "EPICS_CA_ADDR_LIST": "127.0.0.1",
        "EPICS_CA_AUTO_ADDR_LIST": "NO",
        "EPICS_CAS_INTF_ADDR_LIST": "127.0.0.1",
        "EPICS_CA_MAX_ARRAY_BYTES": "4000000",  # a PFM sweep's rows
        "EPICS_CA_SERVER_PORT": str(free_port()),  # the IOCs started from here inherit it
    }
)

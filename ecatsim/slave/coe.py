"""CoE over the mailbox: SDO server, SDO Information; other services are refused.

Ref: ETG.1000.6 §5.6 (CoE), Table 29 (services).
"""

from __future__ import annotations

from collections.abc import Callable

from ecatsim.slave.mailbox import MailboxEngine, MailboxError, Request
from ecatsim.slave.od import ObjectDictionary
from ecatsim.slave.sdo import SdoServer
from ecatsim.slave.sdo_info import SdoInfo
from ecatsim.wire.mailbox import CoeService, MbxError, MbxType


class CoeProtocol:
    """Dispatches CoE services of one slave."""

    def __init__(self, mbx: MailboxEngine, od: ObjectDictionary, state: Callable[[], int]) -> None:
        self.mbx = mbx
        self.od = od
        self.sdo = SdoServer(od, state, mbx.max_body)
        self.info = SdoInfo(od)
        mbx.register(MbxType.COE, self.handle)

    def handle(self, req: Request) -> list[tuple[int, bytes]]:
        """One CoE mailbox. Ref: ETG.1000.6 §5.6.1 (CoE header)."""
        if len(req.data) < 2:
            raise MailboxError(MbxError.SIZE_TOO_SHORT)
        service = req.data[1] >> 4
        if service == CoeService.SDO_REQUEST:
            r = self.sdo.handle(req.data)
            return [] if r is None else [(MbxType.COE, r)]
        if service == CoeService.SDO_INFO:
            return [(MbxType.COE, f) for f in self.info.handle(req.data, self.mbx.max_body())]
        raise MailboxError(MbxError.SERVICE_NOT_SUPPORTED)

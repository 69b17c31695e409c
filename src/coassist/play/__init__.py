"""A person in the loop: ``coassist play``, the operator's live page, and the browser as the hand.

- :mod:`coassist.play.hand`: the pointer pulls the tool through a virtual spring-damper.
- :mod:`coassist.play.world`: the point-mass robot paced to the wall clock (an effort world).
- :mod:`coassist.play.session`: the thesis' protocol for a person; trials saved as a dataset.
- :mod:`coassist.play.protocol`: the page's messages and their validation.
- :mod:`coassist.play.server`: Starlette + uvicorn (the optional ``web`` extra).
"""

from coassist.play.hand import BrowserHand, SpringDamper
from coassist.play.protocol import InvalidMessage, parse_message
from coassist.play.session import PlayConfig, PlaySession, TrialResult
from coassist.play.world import PlayWorld

__all__ = [
    "BrowserHand",
    "InvalidMessage",
    "PlayConfig",
    "PlaySession",
    "PlayWorld",
    "SpringDamper",
    "TrialResult",
    "parse_message",
]

"""coassist: assistive pHRI with a cooperative game-theoretic MPC and learned human intent."""

__version__ = "0.1.0"

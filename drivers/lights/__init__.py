"""Light drivers: each implements only its wire format on top of ``LightBase``."""

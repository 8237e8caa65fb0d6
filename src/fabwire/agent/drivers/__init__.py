"""Per-kind drivers: how a session monitors and commands each kind of device."""

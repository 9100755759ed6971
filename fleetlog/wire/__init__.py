"""fleetlog's convention for MOOS data on Zenoh: keys, payloads, attachments (pure code)."""

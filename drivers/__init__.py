"""Device drivers for the HydroJet bench: one subpackage per device, each with a pure codec,
an async client over a transport chosen by URL, and a byte-level emulator."""

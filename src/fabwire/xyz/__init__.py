"""XYZprinting da Vinci printers over the XYZv3 protocol: codec, status, client, simulator and CLI."""

"""Browse mDNS/DNS-SD from one interface address for a few seconds and print what answers, as JSON lines:
`{"type", "name", "addresses", "port", "txt"}`. Run as a program (inside a test network namespace):
    python mdns_browse.py 10.77.0.2 4 _octoprint._tcp.local. _moonraker._tcp.local."""

from __future__ import annotations

import json
import sys
import time
from typing import Any

from zeroconf import IPVersion, ServiceBrowser, ServiceListener, Zeroconf


class Collect(ServiceListener):
    def __init__(self) -> None:
        self.found: dict[tuple[str, str], dict[str, Any]] = {}

    def add_service(self, zc: Zeroconf, type_: str, name: str) -> None:
        info = zc.get_service_info(type_, name, 3000)
        if info is not None:
            self.found[(type_, name)] = {
                "type": type_, "name": name, "addresses": info.parsed_addresses(), "port": info.port,
                "txt": {k.decode(): (v or b"").decode() for k, v in info.properties.items()}}

    def update_service(self, zc: Zeroconf, type_: str, name: str) -> None:
        self.add_service(zc, type_, name)

    def remove_service(self, zc: Zeroconf, type_: str, name: str) -> None:
        self.found.pop((type_, name), None)


def main() -> None:
    address, seconds, *types = sys.argv[1:]
    zc = Zeroconf(interfaces=[address], ip_version=IPVersion.V4Only)
    collect = Collect()
    browsers = [ServiceBrowser(zc, t, collect) for t in types]
    time.sleep(float(seconds))
    for browser in browsers:
        browser.cancel()
    for entry in collect.found.values():
        print(json.dumps(entry))
    zc.close()


if __name__ == "__main__":
    main()

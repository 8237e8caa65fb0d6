"""Every check of a device address, a device name, a device setting and an uploaded file's name, as one table.

Each door that takes one (`fabwire devices add NAME ADDRESS --set K=V`, `-d ADDRESS` of every device command,
`fabwire serve --device NAME:KIND=ADDRESS`, devices.toml, the agent API's device list) runs the same code
(`fabwire.transport.urls.parse_url`, `check_device_name`, `fabwire.config.validate_settings`), and that code
words each refusal from its row here: the same input is refused with the same line, whichever door it came in by.
Outside text in a refusal is shown with `fabwire.errors.excerpt`, so a refusal is one short line.

Each row says what is refused, the reason given (a template: its fields are filled in by the check), and where the
limit comes from.
"""

from __future__ import annotations

import re
from typing import Literal

import msgspec

from fabwire.errors import InputError

Door = Literal["address", "simulator", "name", "setting", "file"]


class Rule(msgspec.Struct, frozen=True):
    door: Door
    """What the rule checks: an address's form, a sim:// address's simulator and options, a device name, a
    setting given with --set, the name an upload is kept under in the agent's file library."""
    refused: str
    why: str
    """The reason as the refusal says it: a str.format template of the check's fields."""
    source: str


ADDRESS_FORMS = "use host, host:port, tcp://host:port, /dev/ttyX, serial:///dev/ttyX or sim://name"
"""Appended to an address-form refusal: what an address looks like."""
MAX_PATH = 4096
"""The longest device path (or simulator state file): Linux PATH_MAX."""
MAX_NAME = 64
"""The longest device name."""
CONTROL = re.compile(r"[\x00-\x1f\x7f-\x9f]")
"""C0 and C1 control characters (a line break, a tab, NUL …): no address holds one, written or %-encoded."""
INVISIBLE = re.compile(r"[^\S \t]|[\u200b-\u200f\u2060\ufeff]")
"""Blanks other than ASCII space and tab (no-break, ideographic and other spaces, line and paragraph separators)
and invisible format characters (zero-width space and joiners, word joiner, byte order mark): copied along with an
address from a web page or a document, they look like nothing and name another host."""
ASCII_BLANKS = " \t\r\n"
"""What is taken off an address's ends: the blanks and line end a copy in a terminal brings."""
NUMERIC_HOST = re.compile(r"(?:0[xX][0-9a-fA-F]*|[0-9]+)(?:\.(?:0[xX][0-9a-fA-F]*|[0-9]+))*\.?")
"""A host the resolver reads as a number (`RULES["ipv4-form"]`): inet_aton's forms, decimal, octal and hex."""
NAME_CHARACTERS = "letters, digits, '.', '_' and '-', starting with a letter or digit"
FILE_NAME_MAX = 200
"""The longest library name of an upload (folders included): ext4's 255-byte name limit in UTF-8 with room for the
library's own suffixes."""
FILE_RESERVED = re.compile(r"[\\:*?\"<>|]")
"""The characters Windows reserves in a file name (a library is copied off to any system)."""
FILE_HIDDEN = re.compile(r"[\x00-\x1f\x7f-\x9f\u00ad\u034f\u061c\u115f\u1160\u180e\u200b\u200e\u200f\u2028-\u202e"
                         r"\u2060-\u206f\u2800\u3164\ufeff\uffa0\ufff9-\ufffb\ud800-\udfff\U0001d173-\U0001d17a"
                         r"\U000e0000-\U000e007f]")
"""Characters that hide or change what a file name shows: C0 and C1 controls (a terminal's escape sequences, line
breaks, NUL), the soft hyphen, the combining grapheme joiner, the bidirectional controls (marks, embeddings,
overrides, isolates) that make `gcode.exe` read as `exe.gcode`, invisible format characters (zero-width space, word
joiner, invisible operators, the deprecated format characters U+206A-206F, byte order mark, interlinear annotation,
musical formatting, tags), blanks that look like nothing (Hangul fillers, braille blank), line and paragraph
separators, and lone surrogates (undecodable bytes). Zero-width (non-)joiners and variation selectors are kept:
Persian, Indic scripts and emoji are spelt with them."""

RULES: dict[str, Rule] = {
    # ------------------------------------------------------------------------------------------ address forms
    "empty": Rule("address", "an empty address", "it is empty",
                  "RFC 3986 §3.2.2: an address names a host (or a device path); an empty one names nothing"),
    "path-too-long": Rule("address", f"a device path longer than {MAX_PATH} characters",
                          f"the device path is {{length}} characters long, more than the {MAX_PATH} a path may have",
                          "Linux PATH_MAX (4096, <linux/limits.h>): the longest path open() takes"),
    "control": Rule("address", "a control character (line break, tab, NUL …) in an address",
                    "it holds a control character {char}",
                    "RFC 3986 §2: a URI is printable characters; devices.toml keeps an address on one line"),
    "invisible": Rule("address", "a blank other than an ASCII space or tab, or an invisible character, anywhere in an "
                                 "address (U+00A0 no-break space, U+2028, U+200B zero-width space, U+FEFF)",
                      "it holds {char}, which looks like nothing or a space: type the address again",
                      "Unicode's White_Space property and format characters (Cf) that render as nothing; RFC 3986 "
                      "§2: a URI is ASCII"),
    "scheme": Rule("address", "a scheme other than tcp://, serial:// and sim://", "unknown scheme {scheme}",
                   "RFC 3986 §3.1 (scheme); fabwire opens TCP, serial ports and its own simulators"),
    "tcp-path": Rule("address", "a path or options after a tcp:// address", "a tcp:// address takes no path or options",
                     "RFC 793 §2.7: a TCP connection is a host and a port, nothing more"),
    "no-host": Rule("address", "a tcp:// address or host:port without a host", "no host name",
                    "RFC 3986 §3.2.2: the authority's host is required"),
    "host": Rule("address", "a host that is neither a host name nor an IP address",
                 "{host} is not a valid host name or IP address",
                 "RFC 1123 §2.1 and RFC 1035 §2.3.4 (labels of letters, digits and '-', 63 each, 253 in all); "
                 "RFC 791 and RFC 4291 §2.2 (IP addresses)"),
    "ipv4-form": Rule("address", "a host of digits (and 0x hex) that is not four decimal numbers 0-255: 192.168.1, "
                                 "2130706433, 0x7f000001, 0177.0.0.1, 192.168.1.256",
                      "{host} is not a whole IPv4 address (four numbers 0 to 255): the resolver would take it for "
                      "another address or none",
                      "inet_aton(3): a.b.c and a.b are shortened forms, one number is the whole address, 0x is hex "
                      "and a leading 0 octal (192.168.1 reaches 192.168.0.1); RFC 3986 §7.4"),
    "bracket": Rule("address", "an IPv6 literal without its closing ']'", "unclosed '[' in IPv6 address",
                    "RFC 3986 §3.2.2: IP-literal = \"[\" IPv6address \"]\""),
    "after-bracket": Rule("address", "text after an IPv6 literal's ']' other than :port", "unexpected text after ']'",
                          "RFC 3986 §3.2.2: authority = host [\":\" port]"),
    "empty-port": Rule("address", "a ':' with no port after it", "empty port after ':'",
                       "RFC 3986 §3.2.3: an empty port's ':' should be omitted; here it is most likely a typo"),
    "port-digits": Rule("address", "a port that is not a few ASCII digits", "port {port} is {what}",
                        "RFC 3986 §3.2.3: port = *DIGIT (ASCII digits)"),
    "port-range": Rule("address", "port 0 and ports above 65535", "port {port} is outside 1-65535",
                       "RFC 793 §3.1: a TCP port is 16 bits; port 0 cannot be connected to (RFC 6335 §6)"),
    "no-port": Rule("address", "a host without a port for a device with no TCP port (the MMU)",
                    "no port given and {kind} has no default TCP port",
                    "fabwire.devices: the MMU's link is a UART, so it has no port of its own on a network"),
    "serial-path": Rule("address", "a serial:// address whose path is not absolute",
                        "a serial:// address needs an absolute device path, e.g. serial:///dev/ttyACM0",
                        "RFC 8089 §2: file-style URIs hold an absolute path"),
    # ------------------------------------------------------------------------------------------ sim:// addresses
    "sim-path": Rule("address", "a path after sim://name", "a sim:// address takes no path",
                     "RFC 3986 §3.3: sim:// names a simulator by its host part; only options follow"),
    "fragment": Rule("address", "a '#fragment' after an address", "a device address takes no '#' fragment",
                     "RFC 3986 §3.5: a fragment is for the client, never sent; here it would be dropped unseen"),
    "sim-query": Rule("address", "options that are not name=value pairs joined by '&'",
                      "unreadable options {query}",
                      "WHATWG URL Standard §5.1, application/x-www-form-urlencoded parsing"),
    "sim-unknown": Rule("simulator", "a simulator fabwire does not have", "no simulator called {name} (known: {known})",
                        "fabwire.transport.simaddress.SIMULATORS: the simulators fabwire ships (and any registered)"),
    "sim-kind": Rule("simulator", "a simulator of another kind of device than the one asked for",
                     "sim://{name} simulates {simulated}, not {wanted}",
                     "fabwire.devices.KINDS: each simulator is one kind of device"),
    "sim-option": Rule("simulator", "an option the simulator does not have",
                       "sim://{name} has no option {option}{hint}; it takes {known}",
                       "fabwire.transport.simaddress.SIMULATORS: each simulator's table of options"),
    "sim-repeated": Rule("simulator", "an option given twice", "sim://{name} option {option} is given twice",
                         "RFC 3986 §3.4 leaves repeated keys to the application: a simulator takes one value each"),
    "sim-value": Rule("simulator", "an option value the simulator cannot take",
                      "sim://{name} option {option}: {problem}",
                      "fabwire.transport.simaddress.SIMULATORS: each option's row says what it takes and why"),
    # ------------------------------------------------------------------------------------------ device names
    "name-length": Rule("name", f"an empty name, or one longer than {MAX_NAME} characters",
                        f"a device name is 1 to {MAX_NAME} characters, not {{length}}",
                        "one bound for every door: the agent API's NewDevice.name (64), a line of `devices list`"),
    "name-address": Rule("name", "a name -d would read as an address (':' or '/' in it, an IP address, COM3)",
                         "{name} reads as an address, so as a name it would hide that address from -d: choose a name "
                         "without ':', '/' or an IP address's form",
                         "fabwire.config.resolve_target: a -d value with ':' or '/' is an address; "
                         "RFC 791 / RFC 4291 §2.2 address forms; Windows serial port names (COM1-COM256)"),
    "name-host": Rule("name", "a host name of the local network: localhost, or one ending in .local, .lan, .home, "
                              ".home.arpa, .internal or .localdomain (pr.local)",
                      "{name} is a host name, so as a name it would hide that host from -d: choose a name that does "
                      "not end in a local network's domain",
                      "fabwire.config.resolve_target: a -d value that is no configured name is taken as a host; "
                      "RFC 6761 §6.3 (localhost), RFC 6762 (.local, mDNS), RFC 8375 (.home.arpa), ICANN's "
                      "2024 reservation of .internal, and the names home routers give (.lan, .home, .localdomain)"),
    "name-characters": Rule("name", "a name with characters other than letters, digits, '.', '_' and '-', or one "
                                    "starting with '.', '_' or '-'",
                            f"a device name is {NAME_CHARACTERS}, not {{name}}",
                            "POSIX portable filename character set (IEEE Std 1003.1-2017 §3.282): a name is one "
                            "shell word without quotes (completion inserts it as it is), never read as an option "
                            "(POSIX Utility Syntax Guideline 5), a TOML key"),
    # ------------------------------------------------------------------------------------------ uploaded file names
    "file-empty": Rule("file", "an upload without a file name", "the upload has no file name",
                       "RFC 7578 §4.2: a file part names its file in Content-Disposition's filename"),
    "file-part": Rule("file", "a '.' or '..' folder, a Windows-reserved character (\\ : * ? \" < > |), blanks at "
                              "either end of a part",
                      "{part} is not a usable file or folder name",
                      "POSIX path resolution (IEEE Std 1003.1-2017 §4.13: '.' and '..'); Microsoft, \"Naming Files, "
                      "Paths, and Namespaces\" (reserved characters, names ending in a space)"),
    "file-hidden": Rule("file", "a character that hides or changes what the name shows (a control character, "
                                "U+202E right-to-left override, U+200B zero-width space, U+FEFF)",
                        "the file name holds {char}, which hides or changes what the name shows: rename the file",
                        "Unicode UAX #9 (Bidi_Control characters), CVE-2021-42574 (\"Trojan Source\"), Unicode "
                        "UTS #39 §3.3 (default-ignorable characters in identifiers)"),
    "file-length": Rule("file", f"a name longer than {FILE_NAME_MAX} characters with its folders",
                        f"the file name is {{length}} characters long; at most {FILE_NAME_MAX} are kept",
                        "ext4 (and most file systems): 255 bytes per name"),
    # ------------------------------------------------------------------------------------------ --set settings
    "set-form": Rule("setting", "a --set without KEY=VALUE", "--set takes KEY=VALUE, not {text}",
                     "fabwire devices add --help"),
    "set-reserved": Rule("setting", "--set kind=, url= or default=",
                         "give {key} as an argument or option, not with --set",
                         "fabwire devices add: KIND, ADDRESS and --default are its own arguments and option"),
    "set-unknown": Rule("setting", "a setting the kind does not have", "{title} has no setting {key}{hint}",
                        "fabwire.config.SCHEMAS: each kind's typed schema of settings"),
    "set-control": Rule("setting", "a control character in a setting's text",
                        "{key}: {value} holds a control character (a line break, a tab …): a setting is one line of "
                        "text", "TOML v1.0.0, Strings: a basic string holds no raw control characters"),
    "set-value": Rule("setting", "a value of the wrong type or outside its range", "{title}: {problem}",
                      "fabwire.config.SCHEMAS: each setting's type and bounds (msgspec.Meta)"),
    "set-model": Rule("setting", "a printer model the model table does not have", "{problem}",
                      "fabwire.xyz.models.MODELS: the da Vinci models and their model numbers"),
}


def refuse(code: str, **fields: object) -> InputError:
    """The InputError of rule `code`, its reason filled in with `fields` (outside text already shortened)."""
    rule = RULES[code]
    why = rule.why.format(**fields)
    if rule.door == "address":
        address = fields.get("address", "")
        return InputError(f"malformed device address {address}: {why} ({ADDRESS_FORMS})")
    return InputError(why)


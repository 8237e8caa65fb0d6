"""The Line-us as a vpype output: `lineus-fit`, `lineus-stat`, `lineus-preview`, `lineus-draw` and `lineus-gcode`
commands, registered under vpype's `vpype.plugins` entry point group (install `fabwire[vpype]`).

A vpype document's page is read as the Line-us page: CSS pixels (1/96 in) with y down, its top-left corner at the
corner of the app drawing area, exactly as `fabwire lineus draw` places an unfitted SVG. Each vpype layer is one
drawing pass; the arm parks between passes for a pen change.
"""

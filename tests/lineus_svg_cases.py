"""SVG test documents over the feature classes the reader handles, in the manner of a renderer conformance suite:
each a 200 x 200 px page whose ink a browser and the plan are compared on. Strokes are 2 px wide, so the ink of a
stroke is its centre line and the ink of a fill is its border (what a pen draws of it).

CASES maps a case name to (SVG document, feature class). Feature classes are the rows of
fabwire.lineus.plot.svg.FEATURES; every row has cases here.
"""

from __future__ import annotations

HEAD = ('<svg xmlns="http://www.w3.org/2000/svg" xmlns:xlink="http://www.w3.org/1999/xlink" width="200" '
        'height="200"')
S = 'fill="none" stroke="black" stroke-width="2"'
"""A plain 2 px black stroke."""


def doc(body: str, attrs: str = "") -> str:
    return f"{HEAD} {attrs}>{body}</svg>"


CASES: dict[str, tuple[str, str]] = {
    # -- basic shapes and path data --------------------------------------------------------------------------
    "shapes": (doc(f'<rect x="20" y="20" width="60" height="40" {S}/><circle cx="140" cy="50" r="30" {S}/>'
                   f'<ellipse cx="60" cy="140" rx="40" ry="20" {S}/><line x1="110" y1="110" x2="180" y2="180" {S}/>'
                   f'<polyline points="110,180 140,120 170,170" {S}/>'), "shapes"),
    "polygon filled": (doc('<polygon points="30,30 170,40 100,170"/>'), "shapes"),
    "rounded rect": (doc(f'<rect x="30" y="30" width="140" height="100" rx="25" {S}/>'), "shapes"),
    "relative path": (doc(f'<path d="m20 20 h60 v60 h-60 z m100 0 l40 0 l0 40 z" {S}/>'), "shapes"),
    "filled path with hole evenodd": (doc('<path fill-rule="evenodd" d="M20 20 H180 V180 H20 Z M60 60 H140 V140 '
                                          'H60 Z"/>'), "shapes"),
    "filled self-crossing star": (doc('<path d="M100 15 l50 160 l-130 -100 h160 l-130 100 z"/>'), "open fill"),
    "filled overlapping subpaths": (doc('<path d="M20 20 H120 V120 H20 Z M80 80 H180 V180 H80 Z"/>'), "open fill"),
    "filled path with hole nonzero": (doc('<path d="M20 20 H180 V180 H20 Z M60 60 V140 H140 V60 Z"/>'), "shapes"),
    "path without a moveto draws nothing": (doc(f'<path d="L 20 20 L 180 180" {S}/><path d="A 5 5 0 0 1 50 50" '
                                                f'{S}/><rect x="20" y="120" width="60" height="60" {S}/>'), "shapes"),
    "geometry properties in css": (doc(f'<style>#r {{ height: 120px; x: 40px }} circle {{ r: 30px }}</style>'
                                       f'<rect id="r" x="10" y="20" width="100" {S}/>'
                                       f'<circle cx="150" cy="150" r="5" {S} style="cx: 140px"/>'), "css cascade"),
    # -- curves ------------------------------------------------------------------------------------------------
    "curves and arcs": (doc(f'<path d="M20 100 C20 20 100 20 100 100 S180 180 180 100" {S}/>'
                            f'<path d="M20 180 Q60 120 100 180 T180 180" {S}/>'), "curves"),
    "arcs": (doc(f'<path d="M30 60 A40 30 0 0 1 110 60 A40 40 0 1 0 170 140" {S}/>'
                 f'<path d="M30 150 a30 20 45 1 1 60 0" {S}/>'), "curves"),
    "arc radii scaled up": (doc(f'<path d="M40 100 A10 10 0 0 1 160 100" {S}/>'), "curves"),
    # -- rect radii --------------------------------------------------------------------------------------------
    "rect rx auto": (doc(f'<rect x="20" y="20" width="160" height="80" rx="30" {S}/>'
                         f'<rect x="20" y="120" width="160" height="60" ry="auto" rx="20" {S}/>'), "rect radii"),
    "rect radii clamped": (doc(f'<rect x="20" y="20" width="160" height="160" rx="300" ry="40" {S}/>'),
                           "rect radii"),
    "rect negative rx": (doc(f'<rect x="20" y="20" width="160" height="160" rx="-10" ry="30" {S}/>'), "rect radii"),
    "ellipse rx auto": (doc(f'<ellipse cx="100" cy="100" rx="auto" ry="50" {S}/>'), "rect radii"),
    # -- transforms --------------------------------------------------------------------------------------------
    "nested transforms": (doc(f'<g transform="translate(100 100) rotate(30)"><g transform="scale(1.5 0.8)">'
                              f'<rect x="-40" y="-40" width="80" height="80" {S}/></g></g>'), "transforms"),
    "skew and matrix": (doc(f'<rect x="20" y="20" width="60" height="60" transform="skewX(20)" {S}/>'
                            f'<rect x="0" y="0" width="50" height="50" transform="matrix(1 0.3 -0.2 1 110 100)" {S}/>'),
                        "transforms"),
    "rotate about a point": (doc(f'<rect x="70" y="70" width="60" height="60" transform="rotate(30 100 100)" {S}/>'),
                             "transforms"),
    "css transform": (doc(f'<rect x="0" y="0" width="60" height="60" style="transform: translate(50px, 40px) '
                          f'rotate(0.1turn)" {S}/>'), "css transform"),
    "css transform in a sheet": (doc(f'<style>.t {{ transform: scale(2) translateX(10px) }}</style>'
                                     f'<rect class="t" x="10" y="10" width="40" height="30" {S}/>'), "css transform"),
    "css transform over the attribute": (doc(f'<rect x="0" y="0" width="50" height="50" transform="translate(5 5)" '
                                             f'style="transform: translate(100px, 100px)" {S}/>'), "css transform"),
    "transform-origin": (doc(f'<rect x="70" y="70" width="60" height="60" transform="rotate(45)" '
                             f'transform-origin="100 100" {S}/>'), "transform-origin"),
    "transform-origin keywords": (doc(f'<rect x="50" y="50" width="100" height="100" transform="scale(0.5)" '
                                      f'transform-origin="center" {S}/>'), "transform-origin"),
    "transform-origin percent fill-box": (doc(f'<rect x="40" y="60" width="120" height="80" '
                                              f'style="transform: rotate(90deg); transform-origin: 50% 50%; '
                                              f'transform-box: fill-box" {S}/>'), "transform-origin"),
    "transform-origin in css px": (doc(f'<rect x="20" y="20" width="60" height="60" '
                                       f'style="transform: rotate(180deg); transform-origin: 100px 100px" {S}/>'),
                                   "transform-origin"),
    # -- viewports ---------------------------------------------------------------------------------------------
    "viewbox aspect": (doc(f'<rect x="5" y="5" width="90" height="40" {S}/>',
                           'viewBox="0 0 100 50"'), "viewports"),
    "viewbox slice": (doc('<g fill="none" stroke="black" stroke-width="0.5"><rect x="5" y="5" width="90" '
                          'height="40"/><circle cx="50" cy="25" r="20"/></g>',
                          'viewBox="0 0 100 50" preserveAspectRatio="xMinYMax slice"'), "viewports"),
    "viewbox none": (doc(f'<circle cx="50" cy="25" r="20" {S}/>', 'viewBox="0 0 100 50" preserveAspectRatio="none"'),
                     "viewports"),
    "nested svg clip": (doc(f'<svg x="40" y="40" width="100" height="100" viewBox="0 0 50 50">'
                            f'<circle cx="25" cy="25" r="35" {S}/></svg>'), "viewports"),
    "nested svg overflow visible": (doc(f'<svg x="50" y="50" width="100" height="100" overflow="visible">'
                                        f'<circle cx="50" cy="50" r="70" {S}/></svg>'), "viewports"),
    "nested svg cuts a fill": (doc('<svg x="40" y="40" width="100" height="100"><circle cx="50" cy="50" r="70"/>'
                                   '</svg>'), "clipped fill"),
    "page cuts a fill": (doc('<circle cx="200" cy="100" r="60"/>'), "clipped fill"),
    # -- use ---------------------------------------------------------------------------------------------------
    "use of symbol": (doc('<symbol id="s" viewBox="0 0 10 10"><circle cx="5" cy="5" r="4" fill="none" '
                          'stroke="black" stroke-width="0.25"/></symbol>'
                          '<use href="#s" x="20" y="20" width="80" height="80"/>'
                          '<use xlink:href="#s" x="110" y="110" width="60" height="60"/>'), "use"),
    "use of svg x y": (doc(f'<defs><svg id="v" x="50" y="60" width="80" height="80"><rect x="10" y="10" '
                           f'width="60" height="60" {S}/></svg></defs><use href="#v"/>'
                           f'<use href="#v" x="40" y="40"/>'), "use"),
    "use of g with transform": (doc(f'<defs><g id="g"><rect width="40" height="30" {S}/></g></defs>'
                                    f'<use href="#g" x="20" y="20" transform="rotate(10)"/>'
                                    f'<use href="#g" x="120" y="120"/>'), "use"),
    "symbol transform": (doc('<symbol id="s" transform="skewX(20)"><rect x="20" y="20" width="100" '
                             'height="100"/></symbol><use href="#s"/>'), "use"),
    "display none on the root is ignored": (doc(f'<rect x="20" y="20" width="100" height="100" {S}/>',
                                                'display="none"'), "hidden parts"),
    "mutual use cycle": (doc(f'<use id="u1" href="#u2"/><use id="u2" href="#u1"/>'
                             f'<rect x="40" y="40" width="120" height="120" {S}/>'), "use cycle"),
    "use cycle": (doc(f'<g id="a"><rect x="20" y="20" width="60" height="60" {S}/><use href="#a" x="50"/></g>'
                      f'<rect id="b" x="120" y="120" width="50" height="50" {S}/>'), "use cycle"),
    "use inherits style": (doc('<defs><path id="p" d="M20 20 L180 180"/></defs>'
                               '<use href="#p" stroke="black" stroke-width="2"/>'), "use"),
    # -- CSS ---------------------------------------------------------------------------------------------------
    "css cascade": (doc(f'<style>.axis path, .axis line {{ display: none }} g.hidden > * {{ visibility: hidden }}'
                        f'</style><rect x="20" y="20" width="160" height="160" {S}/>'
                        f'<g class="axis"><path d="M10 190 H190" {S}/><line x1="10" y1="10" x2="10" y2="190" {S}/>'
                        f'</g><g class="hidden"><circle cx="100" cy="100" r="30" {S}/></g>'), "css cascade"),
    "css specificity": (doc('<style>#a { stroke: black } .c { stroke: none } rect { stroke: none }</style>'
                            '<rect id="a" class="c" x="20" y="20" width="160" height="160" fill="none" '
                            'stroke-width="2"/>'), "css cascade"),
    "css important": (doc('<style>.c { display: none !important }</style>'
                          f'<rect class="c" x="20" y="20" width="60" height="60" style="display: inline" {S}/>'
                          f'<rect x="100" y="100" width="60" height="60" {S}/>'), "css cascade"),
    "css siblings and attributes": (doc(f'<style>rect + circle {{ display: none }} [data-x="1"] {{ stroke: none }}'
                                        f' path:first-child {{ stroke: none }}</style>'
                                        f'<g><path d="M10 10 H190" {S}/><rect x="20" y="20" width="60" '
                                        f'height="60" {S}/><circle cx="140" cy="50" r="30" {S}/>'
                                        f'<line data-x="1" x1="10" y1="190" x2="190" y2="190" {S}/>'
                                        f'<line x1="20" y1="150" x2="180" y2="150" {S}/></g>'), "css cascade"),
    "css not and nth": (doc(f'<style>rect:not(.keep) {{ display: none }} circle:nth-of-type(2) '
                            f'{{ visibility: hidden }}</style><rect class="keep" x="20" y="20" width="50" '
                            f'height="50" {S}/><rect x="100" y="20" width="50" height="50" {S}/>'
                            f'<circle cx="50" cy="140" r="30" {S}/><circle cx="140" cy="140" r="30" {S}/>'),
                        "css cascade"),
    "css media print": (doc(f'<style>@media print {{ rect {{ display: none }} }} @media screen {{ circle '
                            f'{{ display: none }} }}</style><rect x="20" y="20" width="60" height="60" {S}/>'
                            f'<circle cx="140" cy="140" r="30" {S}/>'), "css cascade"),
    "css root, universal and attribute word": (doc(f'<style>:root rect {{ stroke: none }} * > [class~=on] '
                                                   f'{{ stroke: black }} circle[r="30"] {{ display: none }}</style>'
                                                   f'<rect class="a on" x="20" y="20" width="60" height="60" {S}/>'
                                                   f'<rect class="a" x="100" y="20" width="60" height="60" {S}/>'
                                                   f'<circle cx="50" cy="140" r="30" {S}/>'
                                                   f'<circle cx="140" cy="140" r="31" {S}/>'), "css cascade"),
    "css later rule of equal specificity wins": (doc('<style>.a { stroke: black } .b { stroke: none }</style>'
                                                     '<rect class="b a" x="20" y="20" width="60" height="60" '
                                                     'fill="none" stroke-width="2"/><circle cx="140" cy="140" '
                                                     'r="30" fill="none" stroke="black" stroke-width="2"/>'),
                                                 "css cascade"),
    "presentation attributes": (doc('<style>rect { stroke: black }</style>'
                                    '<rect x="20" y="20" width="160" height="160" stroke="none" fill="none" '
                                    'stroke-width="2"/><circle cx="100" cy="100" r="40" fill="none" '
                                    'stroke="black" stroke-width="2" style="stroke: none"/>'),
                                "presentation attributes"),
    "inherit": (doc('<g stroke="black" stroke-width="2" fill="none"><g stroke="none">'
                    '<rect x="20" y="20" width="60" height="60" stroke="inherit"/></g>'
                    '<circle cx="140" cy="140" r="30"/></g>'), "inherit"),
    "inherit visibility": (doc(f'<g visibility="hidden"><rect x="20" y="20" width="60" height="60" {S}/>'
                               f'<circle cx="140" cy="140" r="30" visibility="visible" {S}/></g>'), "inherit"),
    "q and rem units": (doc(f'<rect x="30Q" y="30Q" width="150Q" height="1.5rem" {S}/>'
                            f'<circle cx="100" cy="120" r="2rem" {S}/>'), "em units"),
    "em units": (doc(f'<g font-size="20"><rect x="1em" y="1em" width="5em" height="3em" {S}/>'
                     f'<circle cx="6em" cy="7em" r="2ex" {S} font-size="30"/></g>'), "em units"),
    # -- hiding ------------------------------------------------------------------------------------------------
    "hidden parts": (doc(f'<rect x="20" y="20" width="60" height="60" display="none" {S}/>'
                         f'<g opacity="0"><circle cx="140" cy="50" r="30" {S}/></g>'
                         f'<g style="display:none"><line x1="0" y1="0" x2="200" y2="200" {S}/></g>'
                         f'<rect x="100" y="100" width="60" height="60" {S}/>'), "hidden parts"),
    "transparent paints": (doc('<rect x="20" y="20" width="60" height="60" fill="transparent" stroke="none"/>'
                               '<rect x="100" y="20" width="60" height="60" fill-opacity="0"/>'
                               '<rect x="20" y="100" width="60" height="60" fill="rgba(0,0,0,0)"/>'
                               '<rect x="100" y="100" width="60" height="60"/>'), "hidden parts"),
    # -- switch ------------------------------------------------------------------------------------------------
    "switch language": (doc(f'<switch><g systemLanguage="xx-unknown"><circle cx="100" cy="100" r="60" {S}/></g>'
                            f'<g systemLanguage="de, en-GB"><rect x="40" y="40" width="120" height="120" {S}/></g>'
                            f'<g><line x1="0" y1="0" x2="200" y2="200" {S}/></g></switch>'), "switch"),
    "switch extensions": (doc(f'<switch><rect requiredExtensions="http://example.org/x" x="10" y="10" width="50" '
                              f'height="50" {S}/><rect requiredFeatures="http://www.w3.org/TR/SVG11/feature#Shape" '
                              f'x="100" y="100" width="60" height="60" {S}/></switch>'), "switch"),
    "switch takes an unknown svg element": (doc(f'<switch><unknown/><rect x="20" y="20" width="60" height="60" '
                                                f'{S}/></switch><circle cx="140" cy="140" r="30" {S}/>'), "switch"),
    "language outside switch": (doc(f'<rect systemLanguage="zz" x="20" y="20" width="60" height="60" {S}/>'
                                    f'<rect systemLanguage="en" x="100" y="100" width="60" height="60" {S}/>'),
                                "switch"),
    # -- dashes ------------------------------------------------------------------------------------------------
    "dashes": (doc(f'<line x1="10" y1="30" x2="190" y2="30" stroke-dasharray="20 10" {S}/>'
                   f'<rect x="20" y="60" width="160" height="120" stroke-dasharray="15,10" {S}/>'), "dashes"),
    "dash offset and odd count": (doc(f'<line x1="10" y1="40" x2="190" y2="40" stroke-dasharray="20 10 5" '
                                      f'stroke-dashoffset="12" {S}/><circle cx="100" cy="120" r="60" '
                                      f'stroke-dasharray="25" stroke-dashoffset="-7" {S}/>'), "dashes"),
    "dashes scaled": (doc('<g transform="scale(2)"><path d="M10 20 H90 M10 50 Q50 10 90 50" '
                          'stroke-dasharray="8 4" fill="none" stroke="black" stroke-width="1"/></g>'), "dashes"),
    "dashes in error draw solid": (doc(f'<line x1="10" y1="40" x2="190" y2="40" stroke-dasharray="10 -5" {S}/>'
                                       f'<line x1="10" y1="100" x2="190" y2="100" stroke-dasharray="0 0" {S}/>'),
                                   "dashes"),
    "round-cap dots": (doc('<line x1="20" y1="100" x2="180" y2="100" stroke="black" stroke-width="6" '
                           'stroke-linecap="round" stroke-dasharray="0 20"/>'), "dashes"),
    "dashes as css": (doc(f'<style>.d {{ stroke-dasharray: 12px 8px }}</style>'
                          f'<path class="d" d="M20 20 L180 180" {S}/>'), "dashes"),
    "dashes through use and a transform": (doc(f'<defs><path id="p" d="M0 0 H80" stroke-dasharray="10 6" {S}/>'
                                               '</defs><use href="#p" x="20" y="40"/><use href="#p" '
                                               'transform="translate(20 120) rotate(20) scale(1.5 1)"/>'), "dashes"),
    "dashes on a polyline with percentages": (doc(f'<polyline points="20,20 180,20 180,180 20,180" '
                                                  f'stroke-dasharray="5% 3%" stroke-dashoffset="2%" {S}/>'),
                                              "dashes"),
    "dashes along pathLength": (doc(f'<polyline points="20,40 60,80 100,40 140,80 180,40" pathLength="100" '
                                    f'stroke-dasharray="3 3" {S}/><circle cx="100" cy="140" r="40" '
                                    f'pathLength="10" stroke-dasharray="1" stroke-dashoffset="0.5" {S}/>'), "dashes"),
    "dashed fill border stays whole": (doc('<rect x="40" y="40" width="120" height="120" fill="black" '
                                           'stroke="black" stroke-width="2" stroke-dasharray="10 10"/>'), "dashes"),
    "opaque gradient hides what lies under it": (doc(f'<line x1="10" y1="60" x2="190" y2="60" {S}/>'
                                                     f'<line x1="10" y1="150" x2="190" y2="150" {S}/>'
                                                     '<linearGradient id="o"><stop offset="0" stop-color="black"/>'
                                                     '<stop offset="1" style="stop-color: #444"/></linearGradient>'
                                                     '<radialGradient id="p" href="#o"/>'
                                                     '<rect x="50" y="30" width="100" height="60" fill="url(#o)"/>'
                                                     '<rect x="50" y="120" width="100" height="60" fill="url(#p)"/>'),
                                                 "white box over lines"),
    # -- gradients that fade into the paper ---------------------------------------------------------------------
    "gradient from white": (doc('<linearGradient id="g"><stop offset="0" stop-color="white"/>'
                                '<stop offset="1" stop-color="black"/></linearGradient>'
                                '<rect x="20" y="20" width="160" height="160" fill="url(#g)"/>'),
                            "gradient fades into the paper"),
    "gradient from transparent, turned, in user space": (
        doc('<linearGradient id="g" gradientUnits="userSpaceOnUse" x1="20" y1="0" x2="180" y2="0" '
            'gradientTransform="rotate(30 100 100)"><stop offset="0.2" stop-color="white" stop-opacity="0"/>'
            '<stop offset="0.7" stop-color="navy"/></linearGradient>'
            '<circle cx="100" cy="100" r="80" fill="url(#g)"/>'), "gradient fades into the paper"),
    "gradient white in the middle": (doc('<linearGradient id="g" x2="0" y2="1"><stop offset="0" stop-color="teal"/>'
                                         '<stop offset="0.5" stop-color="white"/><stop offset="1" '
                                         'stop-color="purple"/></linearGradient>'
                                         '<rect x="30" y="20" width="140" height="160" fill="url(#g)"/>'),
                                     "gradient fades into the paper"),
    "radial gradient with a white centre": (doc('<radialGradient id="g"><stop offset="0.3" stop-color="white"/>'
                                                '<stop offset="0.6" stop-color="black"/></radialGradient>'
                                                '<rect x="20" y="20" width="160" height="160" fill="url(#g)"/>'),
                                            "gradient fades into the paper"),
    "radial gradient fading out, off-centre focus": (
        doc('<radialGradient id="g" fx="0.35" fy="0.4" r="0.45"><stop offset="0" stop-color="maroon"/>'
            '<stop offset="0.8" stop-color="white"/></radialGradient>'
            '<rect x="20" y="20" width="160" height="160" fill="url(#g)"/>'), "gradient fades into the paper"),
    "repeated gradient stripes": (doc('<linearGradient id="g" x2="0.25" spreadMethod="repeat">'
                                      '<stop offset="0.5" stop-color="black"/><stop offset="0.5" '
                                      'stop-color="white"/></linearGradient><linearGradient id="h" href="#g" '
                                      'spreadMethod="reflect" x2="0.5"/>'
                                      '<rect x="20" y="20" width="160" height="70" fill="url(#g)"/>'
                                      '<rect x="20" y="110" width="160" height="70" fill="url(#h)"/>'),
                                  "gradient fades into the paper"),
    "stroke gradient from white": (doc('<linearGradient id="g"><stop offset="0.3" stop-color="white"/>'
                                       '<stop offset="0.4" stop-color="black"/></linearGradient>'
                                       '<rect x="20" y="20" width="160" height="160" fill="none" '
                                       'stroke="url(#g)" stroke-width="2"/>'
                                       '<rect x="60" y="60" width="80" height="80" fill="none" '
                                       'stroke="url(#g)" stroke-width="20"/>'), "gradient fades into the paper"),
    "wide strokes fading out in user space": (doc('<linearGradient id="g" gradientUnits="userSpaceOnUse" x1="40" '
                                                  'x2="160"><stop offset="0.7" stop-color="black"/><stop offset="1" '
                                                  'stop-color="white"/></linearGradient><rect x="40" y="40" '
                                                  'width="120" height="60" fill="none" stroke="url(#g)" '
                                                  'stroke-width="20"/><path d="M20 180 Q100 80 180 180" fill="none" '
                                                  'stroke="url(#g)" stroke-width="16"/>'),
                                              "gradient fades into the paper"),
    "gradient fill inside a black border": (doc('<linearGradient id="g"><stop offset="0.2" stop-color="white"/>'
                                                '<stop offset="0.3" stop-color="black"/></linearGradient>'
                                                '<rect x="20" y="20" width="160" height="160" fill="url(#g)" '
                                                'stroke="black" stroke-width="2"/>'),
                                            "gradient fades into the paper"),
    "paint in error after a gradient": (doc('<linearGradient id="g"><stop offset="0" stop-color="white"/>'
                                            '<stop offset="1" stop-color="black"/></linearGradient>'
                                            '<rect x="20" y="20" width="160" height="160" '
                                            'fill="url(#g) green icc-color(cmyk, 0.1, 0.5, 0.8, 0)"/>'),
                                        "gradient fades into the paper"),
    "pale and translucent paints are ink": (doc('<rect x="20" y="20" width="70" height="70" '
                                                'fill="rgba(0, 127, 0, 0.5)"/><circle cx="145" cy="55" r="35" '
                                                'fill="yellow"/><rect x="20" y="110" width="70" height="70" '
                                                'fill="#eee"/><circle cx="145" cy="145" r="35" fill="navy" '
                                                'opacity="0.2"/>'), "white fill"),
    "paint too faint at its opacity draws nothing": (doc('<rect x="20" y="20" width="70" height="70" '
                                                         'opacity="0.02"/><g opacity="0.1"><g opacity="0.15">'
                                                         '<circle cx="145" cy="55" r="35"/></g></g>'
                                                         '<g opacity="0.5"><rect x="20" y="110" width="70" '
                                                         'height="70" fill-opacity="0.03"/>'
                                                         '<circle cx="145" cy="145" r="35" fill="navy"/></g>'),
                                                     "white fill"),
    "colours meeting are outlined": (doc('<rect x="20" y="20" width="160" height="160" fill="green"/>'
                                         '<circle cx="100" cy="100" r="50" fill="orange"/>'), "white fill"),
    "stroke of the fill's own colour": (doc('<path d="M100 15 l50 160 l-130 -100 h160 l-130 100 z" fill="black" '
                                            'stroke="#000" stroke-width="2"/>'
                                            '<g color="navy"><path d="M20 20 H120 V120 H20 Z M60 60 H180 V180 '
                                            'H60 Z" fill="currentColor" stroke="rgb(0 0 128)"/></g>'),
                                        "stroke of the fill's own paint"),
    "stroke of the fill's own gradient": (doc('<linearGradient id="g"><stop offset="0" stop-color="navy"/>'
                                              '<stop offset="1" stop-color="teal"/></linearGradient>'
                                              '<path d="M100 15 l50 160 l-130 -100 h160 l-130 100 z" '
                                              'fill="url(#g)" stroke="url(#g)" stroke-width="2"/>'),
                                          "stroke of the fill's own paint"),
    "stroke of another colour crosses the fill": (doc('<path d="M100 15 l50 160 l-130 -100 h160 l-130 100 z" '
                                                      'fill="black" stroke="yellow" stroke-width="2"/>'),
                                                  "stroke of the fill's own paint"),
    "fills of one colour meeting show one shape": (doc('<rect x="20" y="20" width="80" height="80" fill="navy"/>'
                                                       '<rect x="100" y="20" width="80" height="80" '
                                                       'fill="#000080"/><rect x="20" y="100" width="80" '
                                                       'height="80" fill="rgb(0,0,128)"/><rect x="100" y="100" '
                                                       'width="80" height="80" fill="navy" stroke="navy"/>'
                                                       '<circle cx="100" cy="100" r="30" fill="navy"/>'
                                                       '<rect x="60" y="150" width="40" height="40" fill="teal"/>'),
                                                   "fills of one colour"),
    "bars of one colour side by side": (doc(''.join(f'<rect x="{20 + 20 * k}" y="{100 - 10 * k}" width="20" '
                                                    f'height="{80 + 10 * k}" style="fill: #ddd; stroke: #ddd"/>'
                                                    for k in range(8))), "fills of one colour"),
    "checkered pattern cut by the shape's edge": (doc('<pattern id="c" patternUnits="userSpaceOnUse" width="40" '
                                                      'height="40"><rect width="20" height="20" fill="grey"/>'
                                                      '<rect x="20" y="20" width="20" height="20" fill="green"/>'
                                                      '</pattern><path d="M100 15 l50 160 l-130 -100 h160 '
                                                      'l-130 100 z" fill="url(#c)"/>'), "pattern fill"),
    "clipped bars of one colour, as matplotlib writes them": (
        doc('<clipPath id="axes"><rect x="10" y="10" width="180" height="180"/></clipPath>'
            + ''.join(f'<path d="M{20 + 20 * k} 180 h20 V{100 - 10 * k} h-20 z" clip-path="url(#axes)" '
                      f'style="fill: #1f77b4"/>' for k in range(8))
            + '<g opacity="0.5"><rect x="60" y="20" width="40" height="40" fill="#1f77b4"/></g>'
            + '<rect x="100" y="20" width="40" height="40" fill="#1f77b4"/>'), "fills of one colour"),
    "pattern tiles of one colour show no seams": (doc('<pattern id="p" patternUnits="userSpaceOnUse" width="50" '
                                                      'height="50"><rect width="51" height="51" fill="#aec7e8"/>'
                                                      '<path d="M0 50 L50 0" stroke="black"/></pattern>'
                                                      '<pattern id="q" href="#p" width="40" height="40"/>'
                                                      '<rect x="10" y="10" width="180" height="80" '
                                                      'fill="url(#p)"/><circle cx="100" cy="145" r="45" '
                                                      'fill="url(#q)" stroke="black"/>'), "pattern fill"),
    # -- wide strokes --------------------------------------------------------------------------------------------
    "wide strokes": (doc('<rect x="30" y="30" width="140" height="50" fill="none" stroke="black" stroke-width="16"/>'
                         '<path d="M30 120 H90 M30 170 H90" fill="none" stroke="#333" stroke-width="14"/>'
                         '<circle cx="140" cy="145" r="25" fill="none" stroke="black" stroke-width="12"/>'),
                     "wide strokes"),
    "wide stroke caps": (doc('<g fill="none" stroke="black" stroke-width="18"><path d="M40 40 H160"/>'
                             '<path d="M40 100 H160" stroke-linecap="round"/>'
                             '<path d="M40 160 H160" stroke-linecap="square"/></g>'), "wide strokes"),
    "wide stroke joins": (doc('<g fill="none" stroke="black" stroke-width="14">'
                              '<polyline points="20,70 50,20 80,70"/>'
                              '<polyline points="110,70 140,20 170,70" stroke-linejoin="round"/>'
                              '<polyline points="20,170 50,120 80,170" stroke-linejoin="bevel"/>'
                              '<polyline points="110,180 140,110 170,180" stroke-miterlimit="1.5"/></g>'),
                          "wide strokes"),
    "wide stroke dashes and dots": (doc('<path d="M20 50 H180" stroke="black" stroke-width="12" '
                                        'stroke-dasharray="30 15"/><path d="M30 120 H180 M100 170 h0" stroke="black" '
                                        'stroke-width="16" stroke-linecap="round" stroke-dasharray="0 40"/>'),
                                    "wide strokes"),
    "wide stroke over its own fill": (doc('<rect x="50" y="50" width="100" height="100" fill="#222" stroke="#555" '
                                          'stroke-width="30"/>'), "wide strokes"),
    "wide stroke scaled": (doc('<g transform="translate(20 20) scale(4 2)"><path d="M5 10 L35 10 L20 70" '
                               'fill="none" stroke="black" stroke-width="3" stroke-linejoin="round"/></g>'),
                           "wide strokes"),
    "wide stroke hides what lies under it": (doc(f'<line x1="20" y1="100" x2="180" y2="100" {S}/>'
                                                 '<line x1="100" y1="20" x2="100" y2="180" stroke="black" '
                                                 'stroke-width="40"/>'), "wide strokes"),
    "wide stroke painted with a pattern": (doc('<pattern id="t" patternUnits="userSpaceOnUse" width="20" '
                                               'height="20"><rect width="10" height="10"/></pattern>'
                                               '<rect x="43" y="43" width="114" height="114" fill="none" '
                                               'stroke="url(#t)" stroke-width="40"/>'), "wide strokes"),
    "wide stroke clipped by its geometry's bounding box": (
        doc('<clipPath id="b" clipPathUnits="objectBoundingBox"><rect width="0.25" height="1"/></clipPath>'
            '<rect x="50" y="50" width="100" height="100" fill="none" stroke="black" stroke-width="40" '
            'clip-path="url(#b)"/>'), "wide strokes"),
    # -- markers -------------------------------------------------------------------------------------------------
    "markers": (doc('<marker id="m" viewBox="0 0 10 10" refX="5" refY="5" markerWidth="8" markerHeight="8" '
                    'orient="auto"><path d="M0 0 L10 5 L0 10 Z"/></marker>'
                    f'<polyline points="30,170 60,40 120,120 180,30" {S} marker-start="url(#m)" marker-mid="url(#m)" '
                    'marker-end="url(#m)"/>'), "markers"),
    "marker units and fixed orient": (doc('<marker id="q" markerUnits="userSpaceOnUse" markerWidth="30" '
                                          'markerHeight="30" refX="15" refY="15" orient="30deg"><rect x="5" y="5" '
                                          'width="20" height="20"/></marker>'
                                          '<path d="M40 50 H160 M40 150 Q100 90 160 150" fill="none" stroke="black" '
                                          'stroke-width="1" style="marker: url(#q)"/>'), "markers"),
    "marker clipped to its box unless overflow is visible": (
        doc('<marker id="c" markerWidth="10" markerHeight="10" refX="0" refY="0" markerUnits="userSpaceOnUse">'
            '<circle r="30"/></marker><marker id="v" markerWidth="10" markerHeight="10" overflow="visible" '
            'markerUnits="userSpaceOnUse"><circle r="30"/></marker>'
            f'<line x1="50" y1="50" x2="50" y2="50" {S} marker-start="url(#c)"/>'
            f'<line x1="120" y1="130" x2="120" y2="130" {S} marker-end="url(#v)"/>'), "markers"),
    "auto-start-reverse on a closed path": (doc('<marker id="a" viewBox="0 0 10 10" refX="0" refY="5" '
                                                'markerWidth="12" markerHeight="12" orient="auto-start-reverse">'
                                                '<path d="M0 0 L10 5 L0 10 Z"/></marker>'
                                                f'<path d="M40 40 H160 V160 Z" {S} marker-start="url(#a)" '
                                                'marker-end="url(#a)"/>'), "markers"),
    "context paint": (doc('<defs><g id="g"><rect x="20" y="20" width="60" height="60" fill="context-stroke" '
                          'stroke="context-fill" stroke-width="2"/></g></defs>'
                          '<use href="#g" fill="none" stroke="black"/>'
                          '<rect x="120" y="20" width="60" height="60" fill="context-fill"/>'
                          '<marker id="k" markerUnits="userSpaceOnUse" markerWidth="20" markerHeight="20" refX="10" '
                          'refY="10"><circle cx="10" cy="10" r="8" fill="context-stroke"/></marker>'
                          '<path d="M30 150 H170" stroke="#222" stroke-width="2" marker-start="url(#k)" '
                          'marker-end="url(#k)"/>'), "markers"),
    # -- clip paths --------------------------------------------------------------------------------------------
    "clipped fill": (doc('<clipPath id="c"><rect x="0" y="0" width="100" height="200"/></clipPath>'
                         '<circle cx="100" cy="100" r="70" clip-path="url(#c)"/>'), "clipped fill"),
    "clipped stroke": (doc(f'<clipPath id="c"><circle cx="100" cy="100" r="60"/></clipPath>'
                           f'<path d="M0 100 H200 M100 0 V200" {S} clip-path="url(#c)"/>'), "clipped fill"),
    "clip bounding box units": (doc('<clipPath id="c" clipPathUnits="objectBoundingBox"><rect x="0.25" y="0.25" '
                                    'width="0.5" height="0.5"/></clipPath><rect x="20" y="20" width="160" '
                                    'height="160" clip-path="url(#c)"/>'), "clipped fill"),
    "clip by a self-crossing star": (doc('<clipPath id="c"><path d="M100 15 l50 160 l-130 -100 h160 l-130 100 z"/>'
                                         '</clipPath><rect width="200" height="200" clip-path="url(#c)"/>'),
                                     "clipped fill"),
    "transform-origin center on a clip path": (doc('<clipPath id="c" transform="rotate(36)" '
                                                   'transform-origin="center"><rect x="50" y="50" width="100" '
                                                   'height="60"/></clipPath><rect width="200" height="200" '
                                                   'clip-path="url(#c)"/>'), "transform-origin"),
    "transform-origin on a clip path": (doc('<clipPath id="c" transform="rotate(45)" transform-origin="100 100">'
                                            '<rect x="50" y="50" width="100" height="100"/></clipPath>'
                                            '<rect x="20" y="20" width="160" height="160" clip-path="url(#c)"/>'),
                                        "transform-origin"),
    "clip evenodd": (doc('<clipPath id="c"><path clip-rule="evenodd" d="M10 10 H190 V190 H10 Z M60 60 H140 V140 '
                         'H60 Z"/></clipPath><rect x="30" y="30" width="140" height="140" clip-path="url(#c)"/>'),
                     "clipped fill"),
    "clip on a group": (doc('<clipPath id="c"><circle cx="100" cy="100" r="80"/></clipPath>'
                            '<g clip-path="url(#c)"><rect x="10" y="10" width="90" height="90"/>'
                            f'<line x1="0" y1="200" x2="200" y2="0" {S}/></g>'), "clipped fill"),
    "clip path with a transform": (doc('<clipPath id="c" transform="rotate(45 100 100)"><rect x="50" y="50" '
                                       'width="100" height="100"/></clipPath><rect x="40" y="40" width="120" '
                                       'height="120" clip-path="url(#c)"/>'), "clipped fill"),
    "clip-path basic shapes": (doc('<rect x="10" y="10" width="80" height="80" clip-path="circle()"/>'
                                   '<rect x="110" y="10" width="80" height="80" clip-path="ellipse(30% 20px at 40% '
                                   '60%)"/><rect x="10" y="110" width="80" height="80" clip-path="inset(10px 20%)"/>'
                                   '<rect x="110" y="110" width="80" height="80" clip-path="polygon(50% 0, 100% 100%, '
                                   '0 100%)"/>'), "clipped fill"),
    "clip-path basic shape reference boxes": (doc('<rect x="30" y="30" width="60" height="60" fill="#333" '
                                                  'stroke="black" stroke-width="16" clip-path="circle(50% at right '
                                                  'top) fill-box"/><rect x="110" y="110" width="60" height="60" '
                                                  'stroke="black" stroke-width="16" clip-path="circle()"/>'
                                                  '<rect x="110" y="20" width="80" height="60" '
                                                  'clip-path="circle(30px at 150px 50px) view-box"/>'),
                                              "clipped fill"),
    "clipped opaque fill hides what lies under the group": (
        doc(f'<line x1="10" y1="100" x2="190" y2="100" {S}/><line x1="100" y1="10" x2="100" y2="190" {S}/>'
            '<clipPath id="o"><circle cx="100" cy="100" r="50"/></clipPath>'
            '<g clip-path="url(#o)"><rect x="20" y="20" width="160" height="160" fill="#333"/></g>'), "clipped fill"),
    "root clip-path": (doc('<clipPath id="c"><rect x="0" y="0" width="120" height="120"/></clipPath>'
                           f'<rect x="20" y="20" width="160" height="160" {S}/>', 'clip-path="url(#c)"'),
                       "root clip-path"),
    "clip path not displayed": (doc('<clipPath id="c" display="none"><rect width="50" height="50"/></clipPath>'
                                    f'<rect x="20" y="20" width="160" height="160" {S} clip-path="url(#c)"/>'),
                                "clipped fill"),
    "clip cycle": (doc('<clipPath id="a" clip-path="url(#b)"><rect x="20" y="20" width="160" height="160"/>'
                       '</clipPath><clipPath id="b" clip-path="url(#a)"><rect x="0" y="0" width="120" '
                       'height="120"/></clipPath><circle cx="100" cy="100" r="90" clip-path="url(#a)"/>'),
                   "clip cycle"),
    # -- fills -------------------------------------------------------------------------------------------------
    "open fill": (doc('<path d="M20 20 L180 40 L100 180"/><polyline points="20,190 60,120 100,190"/>'), "open fill"),
    "open fill with stroke": (doc('<path d="M20 20 L180 40 L100 180" stroke="black" stroke-width="2"/>'),
                              "open fill"),
    "white fill": (doc(f'<rect width="200" height="200" style="fill: #ffffff"/><path d="M20 100 Q100 0 180 100" '
                       f'{S}/>'), "white fill"),
    "paper-coloured paints": (doc('<rect x="10" y="10" width="80" height="80" fill="white" stroke="#fff"/>'
                                  '<rect x="110" y="10" width="80" height="80" fill="rgb(255 255 255)"/>'
                                  '<rect x="10" y="110" width="80" height="80" fill="black" fill-opacity="0.01"/>'
                                  '<rect x="110" y="110" width="80" height="80" fill="navy"/>'), "white fill"),
    "current colour": (doc('<g color="black"><rect x="20" y="20" width="60" height="60" fill="currentColor"/></g>'
                           '<g color="white"><rect x="100" y="100" width="60" height="60" fill="currentColor"/>'
                           '</g>'), "white fill"),
    "gradient without stops paints nothing": (doc('<linearGradient id="g"/><linearGradient id="h" href="#k"/>'
                                                  '<linearGradient id="k"><stop offset="0"/></linearGradient>'
                                                  '<rect x="20" y="20" width="60" height="60" fill="url(#g)"/>'
                                                  '<rect x="100" y="100" width="60" height="60" fill="url(#h)"/>'),
                                              "white fill"),
    "stroke of no paint server": (doc('<defs><rect id="r" width="5" height="5"/></defs>'
                                      '<rect x="20" y="20" width="60" height="60" fill="none" stroke="url(#r)"/>'
                                      '<rect x="100" y="100" width="60" height="60" fill="none" '
                                      'stroke="url(#none) black" stroke-width="2"/>'), "white fill"),
    "missing paint server": (doc('<rect x="20" y="20" width="60" height="60" fill="url(#nothing)"/>'
                                 '<rect x="100" y="100" width="60" height="60" fill="url(#nothing) black"/>'),
                             "white fill"),
    # -- painting order: opaque fills hide what lies under them ---------------------------------------------
    "white box over lines": (doc(f'<path d="M10 100 H190 M100 10 V190" {S}/><rect x="60" y="60" width="80" '
                                 f'height="80" fill="white" stroke="black" stroke-width="2"/>'), "painting order"),
    "later fill over earlier stroke": (doc(f'<rect x="20" y="20" width="100" height="100" {S}/>'
                                           '<circle cx="120" cy="120" r="60" fill="navy"/>'), "painting order"),
    "translucent fill hides nothing": (doc(f'<path d="M10 100 H190" {S}/><rect x="60" y="60" width="80" '
                                           f'height="80" fill="white" fill-opacity="0.5"/>'), "painting order"),
    "group opacity hides nothing": (doc(f'<path d="M10 100 H190" {S}/><g opacity="0.5"><rect x="60" y="60" '
                                        f'width="80" height="80" fill="white" stroke="black" stroke-width="2"/></g>'),
                                    "painting order"),
    "fill over a clipped group": (doc('<clipPath id="c"><rect width="100" height="200"/></clipPath>'
                                      f'<g clip-path="url(#c)"><path d="M10 100 H190" {S}/></g>'
                                      '<rect x="50" y="50" width="100" height="100" fill="white"/>'), "painting order"),
    # -- patterns ----------------------------------------------------------------------------------------------
    "pattern fill": (doc('<defs><pattern id="h" patternUnits="userSpaceOnUse" width="20" height="20">'
                         '<path d="M0 0 L20 20" stroke="black" stroke-width="2"/></pattern></defs>'
                         '<rect x="20" y="20" width="160" height="160" fill="url(#h)"/>'), "pattern fill"),
    "pattern bounding box units": (doc('<defs><pattern id="h" width="0.25" height="0.25">'
                                       '<line x1="0" y1="10" x2="40" y2="10" stroke="black" stroke-width="2"/>'
                                       '</pattern></defs><circle cx="100" cy="100" r="80" fill="url(#h)"/>'),
                                   "pattern fill"),
    "pattern transform": (doc('<defs><pattern id="h" patternUnits="userSpaceOnUse" width="25" height="25" '
                              'patternTransform="rotate(30)"><line x1="0" y1="12" x2="25" y2="12" stroke="black" '
                              'stroke-width="2"/></pattern></defs>'
                              '<rect x="20" y="20" width="160" height="160" fill="url(#h)"/>'), "pattern fill"),
    "pattern viewbox and href": (doc('<defs><pattern id="base" viewBox="0 0 10 10" patternUnits="userSpaceOnUse" '
                                     'width="30" height="30"><circle cx="5" cy="5" r="3" fill="none" '
                                     'stroke="black" stroke-width="0.6"/></pattern>'
                                     '<pattern id="h" href="#base" x="5" y="5"/></defs>'
                                     '<rect x="20" y="20" width="160" height="160" fill="url(#h)"/>'),
                                 "pattern fill"),
    "pattern with a stroke": (doc('<defs><pattern id="h" patternUnits="userSpaceOnUse" width="16" height="16">'
                                  '<line x1="8" y1="0" x2="8" y2="16" stroke="black" stroke-width="2"/></pattern>'
                                  '</defs><circle cx="100" cy="100" r="80" fill="url(#h)" stroke="black" '
                                  'stroke-width="2"/>'), "pattern fill"),
    # -- length units --------------------------------------------------------------------------------------
    "font-relative units": (doc(f'<rect x="2ch" y="1cap" width="6ex" height="3lh" {S}/>'
                                f'<rect x="3ic" y="100" width="4rem" height="2rlh" {S}/>', 'font-size="20"'),
                            "font-relative units"),
    "font-relative units of a monospace face": (doc(f'<g font-family="monospace" font-size="25"><rect x="1ch" '
                                                    f'y="1ex" width="10ch" height="4lh" {S}/></g>'),
                                                "font-relative units"),
    "root font for rem and rlh": (doc(f'<g font-size="8"><rect x="1rem" y="1rlh" width="5rem" height="3rlh" '
                                      f'{S}/></g>', 'font-size="24" font-family="serif"'), "font-relative units"),
    "viewport units": (doc(f'<rect x="10vw" y="5vh" width="40vmin" height="30vmax" {S}/>'
                           f'<line x1="60vi" y1="80vb" x2="90vw" y2="95vh" {S}/>'), "viewport units"),
    "viewport units under a viewBox": (doc(f'<circle cx="50vw" cy="50vh" r="10vmin" {S}/>', 'viewBox="0 0 100 100"'),
                                       "viewport units"),
    "length in error": (doc(f'<rect x="20" y="20" width="160" height="160" {S}/>'
                            f'<rect x="40" y="40" width="30pxx" height="100" {S}/>'
                            f'<circle cx="100" cy="100" r="4 0" {S}/><circle cx="100" cy="100" r="40em2" {S}/>'),
                        "length in error"),
    # -- paint servers that are not rendered -------------------------------------------------------------------
    "paint server not rendered": (doc('<defs display="none"><linearGradient id="g"><stop stop-color="black"/>'
                                      '</linearGradient></defs><rect x="20" y="20" width="70" height="70" '
                                      'fill="url(#g)"/><rect x="110" y="110" width="70" height="70" '
                                      'fill="url(#g) black"/>'), "paint server not rendered"),
    "paint server under a failed condition": (doc('<g systemLanguage="x-none"><pattern id="p" width="10" '
                                                  'height="10" patternUnits="userSpaceOnUse"><rect width="5" '
                                                  'height="5"/></pattern></g><circle cx="100" cy="100" r="60" '
                                                  'fill="url(#p)" stroke="black" stroke-width="2"/>'
                                                  '<linearGradient id="g" '
                                                  'systemLanguage="x-none"><stop stop-color="black"/>'
                                                  '</linearGradient><rect x="10" y="10" width="30" height="30" '
                                                  'fill="url(#g)"/>'), "paint server not rendered"),
    # -- bounding boxes --------------------------------------------------------------------------------------------
    "bbox of hidden children": (doc('<clipPath id="c" clipPathUnits="objectBoundingBox"><rect x="0.5" y="0" '
                                    'width="0.5" height="1"/></clipPath><g clip-path="url(#c)">'
                                    '<rect x="10" y="10" width="100" height="180" visibility="hidden"/>'
                                    '<circle cx="150" cy="60" r="10" opacity="0"/>'
                                    '<rect x="120" y="120" width="40" height="60" fill="none" stroke="none"/>'
                                    '<g opacity="0"><line x1="0" y1="100" x2="200" y2="100" stroke="black"/></g>'
                                    '<rect x="60" y="40" width="80" height="120"/></g>'), "bbox of hidden children"),
    # -- clip path transforms, group compositing ---------------------------------------------------------------
    "clip path transform by bounding box": (doc('<clipPath id="c" clipPathUnits="objectBoundingBox" '
                                                'transform="translate(20 10)"><rect width="0.5" height="0.5"/>'
                                                '</clipPath><rect x="40" y="40" width="120" height="120" '
                                                'clip-path="url(#c)"/>'), "clip path transform by bounding box"),
    "clip path transform-origin by bounding box": (doc('<clipPath id="c" clipPathUnits="objectBoundingBox" '
                                                       'transform="scale(1.5)" transform-origin="center">'
                                                       '<circle cx="0.5" cy="0.5" r="0.3"/></clipPath>'
                                                       '<rect x="20" y="50" width="140" height="100" '
                                                       'clip-path="url(#c)"/>'),
                                                   "clip path transform by bounding box"),
    "fill hides lines within a translucent group": (doc('<g opacity="0.6"><line x1="10" y1="100" x2="190" '
                                                        'y2="100" stroke="black" stroke-width="2"/>'
                                                        '<circle cx="100" cy="100" r="50"/>'
                                                        '</g>'), "fill hides lines within a translucent group"),
    "fill hides lines within a clipped group": (doc('<clipPath id="c"><rect x="0" y="0" width="150" '
                                                    'height="200"/></clipPath><g clip-path="url(#c)">'
                                                    f'<path d="M20 40 L180 160" {S}/><rect x="60" y="60" '
                                                    'width="80" height="80"/></g>'),
                                                "fill hides lines within a translucent group"),
}

TEXT_CASES: dict[str, str] = {
    "text": doc('<text x="20" y="60" font-size="32">Plotter</text>'),
    "text anchor middle": doc('<text x="100" y="100" font-size="24" text-anchor="middle">centred</text>'),
    "text anchor end": doc('<text x="180" y="150" font-size="20" text-anchor="end" font-family="serif">the end'
                           '</text>'),
    "text transformed": doc('<text x="0" y="0" font-size="20" transform="translate(40 40) rotate(30)">turned'
                            '</text>'),
    "text tspans": doc('<text x="20" y="50" font-size="20">first <tspan x="20" y="100" font-size="30">second'
                       '</tspan><tspan dx="10">third</tspan></text>'),
    "text in a styled group": doc('<g font-family="serif" font-size="24" transform="translate(10 0)">'
                                  '<text x="30" y="80">Serif text</text></g>'),
    "text preserving spaces": doc('<text x="20" y="100" font-size="20" xml:space="preserve">a   b</text>'),
    "unpainted and white text leaves no letters": doc('<text x="10" y="100" font-size="20"><tspan fill="none">ab'
                                                      '</tspan> <tspan fill="white">cd</tspan> <tspan '
                                                      'fill-opacity="0">ef</tspan> shown</text>'),
    "text css font size": doc('<style>text { font-size: 2em }</style><text x="20" y="120">Big</text>'),
}
"""Text cases: the letters differ from the browser's font, so these are compared by the box the ink covers."""

#!/usr/bin/env python3
"""Draws the car's wiring (docs/img/wiring.svg) from the pins in config/car.toml.

    python3 docs/img/wiring.py            write docs/img/wiring.svg
    python3 docs/img/wiring.py --check    exit 1 if the checked-in picture is out of date
    python3 docs/img/wiring.py --table    print the wiring table (Markdown) for docs/pi.md

The Raspberry Pi pins are BCM numbers from the `[gpio]` section (button_pin, led_pin,
trig_pin, echo_pin); when the section is missing the defaults of src/gpio (17, 27, 23, 24)
are drawn. The Arduino pins are fixed by the firmware (Timer1: D9 = OC1A steering servo,
D10 = OC1B ESC). The HC-SR04's ECHO is a 5 V signal: it reaches the Pi through a divider,
Vout = 5 V x R2 / (R1 + R2), with R1 = 1 kOhm in series and R2 = 2 kOhm to ground:
3.33 V. Standard library only (tomllib: Python 3.11+, Debian 12's python3).
"""
import pathlib
import sys
import tomllib

ROOT = pathlib.Path(__file__).resolve().parents[2]
CONFIG = ROOT / "config" / "car.toml"
OUT = ROOT / "docs" / "img" / "wiring.svg"
DEFAULT_PINS = {"button_pin": 17, "led_pin": 27, "trig_pin": 23, "echo_pin": 24}
R1_OHM, R2_OHM, ECHO_V = 1000.0, 2000.0, 5.0
LED_OHM = 330

# The 40-pin header: physical pin -> name (the same on every 40-pin Pi, 1 B+ .. 5).
HEADER = {
    1: "3V3", 2: "5V", 3: "GPIO2", 4: "5V", 5: "GPIO3", 6: "GND", 7: "GPIO4", 8: "GPIO14",
    9: "GND", 10: "GPIO15", 11: "GPIO17", 12: "GPIO18", 13: "GPIO27", 14: "GND",
    15: "GPIO22", 16: "GPIO23", 17: "3V3", 18: "GPIO24", 19: "GPIO10", 20: "GND",
    21: "GPIO9", 22: "GPIO25", 23: "GPIO11", 24: "GPIO8", 25: "GND", 26: "GPIO7",
    27: "GPIO0", 28: "GPIO1", 29: "GPIO5", 30: "GND", 31: "GPIO6", 32: "GPIO12",
    33: "GPIO13", 34: "GND", 35: "GPIO19", 36: "GPIO16", 37: "GPIO26", 38: "GPIO20",
    39: "GND", 40: "GPIO21",
}


def physical(bcm):
    """Header pin number of BCM pin `bcm`."""
    for pin, name in HEADER.items():
        if name == f"GPIO{bcm}":
            return pin
    sys.exit(f"{CONFIG}: [gpio] BCM pin {bcm} is not on the 40-pin header (2..27)")


def pins():
    """The BCM pins from config/car.toml [gpio], and whether they came from there."""
    try:
        with open(CONFIG, "rb") as f:
            cfg = tomllib.load(f)
    except (OSError, tomllib.TOMLDecodeError) as e:
        sys.exit(f"{CONFIG}: {e}")
    g = cfg.get("gpio")
    if not isinstance(g, dict):
        return dict(DEFAULT_PINS), False
    out = {}
    for k, v in DEFAULT_PINS.items():
        x = g.get(k, v)
        if not isinstance(x, int) or isinstance(x, bool):
            sys.exit(f"{CONFIG}: gpio.{k} = {x!r}: expected a BCM pin number")
        out[k] = x
    return out, True


def echo_volts():
    return ECHO_V * R2_OHM / (R1_OHM + R2_OHM)


def rows(p):
    """The wiring table: (from, to, note)."""
    b, l, t, e = (p[k] for k in ("button_pin", "led_pin", "trig_pin", "echo_pin"))
    return [
        ("Steering servo signal (white/yellow)", "Arduino D9", "Timer1 OC1A, 50 Hz, 1000-2000 µs"),
        ("ESC signal (white/yellow)", "Arduino D10", "Timer1 OC1B, 50 Hz; neutral 1500 µs"),
        ("ESC BEC + (red)", "Servo + (red)", "the ESC's 5-6 V regulator powers the servo; not to the Arduino's 5V"),
        ("ESC − (black/brown), servo −", "Arduino GND", "one common ground for Arduino, ESC and servo"),
        ("Arduino USB", "Pi USB port", "power and serial: /dev/ttyACM0 (Uno) or /dev/ttyUSB0 (CH340 clones)"),
        ("Start/stop button", f"GPIO{b} (pin {physical(b)}) and GND (pin {pin_gnd(physical(b))})",
         "internal pull-up: pressed reads low"),
        ("Status LED anode (+, long leg)", f"GPIO{l} (pin {physical(l)})",
         f"cathode through {LED_OHM} Ω to GND: (3.3 − 2.0 V) / {LED_OHM} Ω ≈ 4 mA"),
        ("HC-SR04 VCC", "Pi 5V (pin 2)", "the sensor needs 5 V"),
        ("HC-SR04 GND", "Pi GND (pin 6)", ""),
        ("HC-SR04 TRIG", f"GPIO{t} (pin {physical(t)})", "3.3 V from the Pi is a valid high for the sensor"),
        ("HC-SR04 ECHO", f"1 kΩ → GPIO{e} (pin {physical(e)}); 2 kΩ from GPIO{e} to GND",
         f"divider: 5 V × 2 k / (1 k + 2 k) = {echo_volts():.2f} V at the pin"),
        ("Pi power", "5 V USB-C supply or a 5 V 3 A UBEC from the drive battery", "not from the Arduino or the ESC's BEC"),
    ]


def pin_gnd(phys):
    """A ground pin near header pin `phys`."""
    grounds = [n for n, name in HEADER.items() if name == "GND"]
    return min(grounds, key=lambda g: (abs(g - phys), g))


def table(p, from_config):
    src = "config/car.toml [gpio]" if from_config else "the defaults of src/gpio (config/car.toml has no [gpio] yet)"
    lines = [f"Pins (BCM numbers, header pin in brackets) from {src}.", "",
             "| from | to | note |", "|---|---|---|"]
    lines += [f"| {a} | {b} | {c} |" for a, b, c in rows(p)]
    return "\n".join(lines)


def esc(s):
    return s.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")


def svg(p, from_config):
    """The picture: Pi header on the left, breadboard parts in the middle, Arduino, ESC and
    servo on the right. Wires are coloured by role: red = 5 V, black = ground, blue = signal."""
    W, H = 990, 620
    o = []
    add = o.append
    add(f'<svg xmlns="http://www.w3.org/2000/svg" width="{W}" height="{H}" viewBox="0 0 {W} {H}" '
        'font-family="DejaVu Sans, Verdana, sans-serif" font-size="13">')
    add('<rect width="100%" height="100%" fill="white"/>')
    add(f'<text x="20" y="28" font-size="18" font-weight="bold">rccar wiring</text>')
    # The same words whether the pins came from the file or the defaults: the picture only
    # changes when a pin does (`--check` in tests/cross/run.sh).
    add('<text x="20" y="48" fill="#555">Pi pins: BCM numbers from config/car.toml [gpio]; '
        'drawn by docs/img/wiring.py</text>')

    def box(x, y, w, h, title, fill):
        add(f'<rect x="{x}" y="{y}" width="{w}" height="{h}" rx="8" fill="{fill}" stroke="#333" stroke-width="1.5"/>')
        add(f'<text x="{x + w / 2}" y="{y + 20}" text-anchor="middle" font-weight="bold">{esc(title)}</text>')

    def wire(points, colour, dash=False):
        d = " ".join(f"{x},{y}" for x, y in points)
        extra = ' stroke-dasharray="6,4"' if dash else ""
        add(f'<polyline points="{d}" fill="none" stroke="{colour}" stroke-width="2.5"{extra}/>')

    def dot(x, y, colour="#333"):
        add(f'<circle cx="{x}" cy="{y}" r="4" fill="{colour}"/>')

    def label(x, y, text, anchor="start", colour="#000", size=12):
        add(f'<text x="{x}" y="{y}" text-anchor="{anchor}" fill="{colour}" font-size="{size}">{esc(text)}</text>')

    RED, BLK, SIG, USB = "#d62728", "#222", "#1f77b4", "#7f7f7f"
    # --- the Pi: the header pins in use, as a column
    px, py = 20, 70
    used = [(2, "5V"), (6, "GND")]
    for k in ("button_pin", "led_pin", "trig_pin", "echo_pin"):
        used.append((physical(p[k]), f"GPIO{p[k]}"))
    used.append((pin_gnd(physical(p["button_pin"])), "GND"))
    box(px, py, 200, 470, "Raspberry Pi", "#e8f5e9")
    label(px + 100, py + 38, "40-pin header (pins in use)", "middle", "#555", 11)
    ys = {}
    for i, (phys, name) in enumerate(used):
        y = py + 70 + i * 52
        ys[name if name.startswith("GPIO") else f"{name}{phys}"] = y
        add(f'<rect x="{px + 150}" y="{y - 9}" width="18" height="18" fill="#ffd54f" stroke="#333"/>')
        label(px + 140, y + 4, f"pin {phys}  {name}", "end")
        ys[(phys, name)] = y
    add(f'<rect x="{px + 20}" y="{py + 430}" width="160" height="26" rx="4" fill="#ccc" stroke="#333"/>')
    label(px + 100, py + 448, "USB port", "middle")
    pin_x = px + 168

    def pin_y(phys, name):
        return ys[(phys, name)]

    # --- breadboard column: button, LED, HC-SR04 with divider
    bx = 330
    b, l, t, e = (p[k] for k in ("button_pin", "led_pin", "trig_pin", "echo_pin"))
    gnd_b = pin_gnd(physical(b))
    yb, yl, yt, ye = (pin_y(physical(v), f"GPIO{v}") for v in (b, l, t, e))
    y5, yg, yg2 = pin_y(2, "5V"), pin_y(6, "GND"), pin_y(gnd_b, "GND")
    # ground rail of the breadboard
    rail_x = 300
    wire([(pin_x, yg), (rail_x, yg), (rail_x, 520)], BLK)
    wire([(pin_x, yg2), (rail_x, yg2)], BLK)
    dot(rail_x, yg2)
    label(rail_x - 6, 536, "GND rail", "middle", "#222", 11)
    # button
    box(bx, yb - 22, 120, 40, "", "#fff3e0")
    label(bx + 60, yb + 3, "push button", "middle")
    wire([(pin_x, yb), (bx, yb)], SIG)
    wire([(bx + 120, yb), (bx + 140, yb), (bx + 140, yb + 26), (rail_x, yb + 26)], BLK)
    dot(rail_x, yb + 26)
    label(bx + 126, yb - 8, "to GND", "start", "#222", 10)
    # LED + resistor
    wire([(pin_x, yl), (bx, yl)], SIG)
    add(f'<polygon points="{bx},{yl - 10} {bx},{yl + 10} {bx + 18},{yl}" fill="#ff8a80" stroke="#333"/>')
    add(f'<line x1="{bx + 18}" y1="{yl - 10}" x2="{bx + 18}" y2="{yl + 10}" stroke="#333" stroke-width="2"/>')
    label(bx + 9, yl - 14, "LED", "middle", "#000", 11)
    add(f'<rect x="{bx + 40}" y="{yl - 6}" width="44" height="12" fill="#d7ccc8" stroke="#333"/>')
    label(bx + 62, yl - 10, f"{LED_OHM} Ω", "middle", "#000", 11)
    wire([(bx + 18, yl), (bx + 40, yl)], BLK)
    wire([(bx + 84, yl), (bx + 140, yl), (bx + 140, yl + 22), (rail_x, yl + 22)], BLK)
    dot(rail_x, yl + 22)
    # HC-SR04
    sx, sy = 560, min(yt, ye) - 50
    box(sx, sy, 150, 150, "HC-SR04", "#e3f2fd")
    for i, n in enumerate(("VCC", "TRIG", "ECHO", "GND")):
        label(sx + 10, sy + 48 + i * 26, n)
    s_vcc, s_trig, s_echo, s_gnd = (sy + 44 + i * 26 for i in range(4))
    wire([(pin_x, y5), (250, y5), (250, 60), (540, 60), (540, s_vcc), (sx, s_vcc)], RED)
    label(546, 100, "5 V", "start", RED, 11)
    wire([(pin_x, yt), (480, yt), (480, s_trig), (sx, s_trig)], SIG)
    label(470, yt - 6, "TRIG (3.3 V out)", "end", SIG, 11)
    # divider: ECHO --1k-- node --2k-- GND, node -> GPIO echo
    node_x = 470
    add(f'<rect x="{510}" y="{s_echo - 6}" width="40" height="12" fill="#d7ccc8" stroke="#333"/>')
    label(530, s_echo - 10, "1 kΩ", "middle", "#000", 11)
    wire([(sx, s_echo), (550, s_echo)], SIG)
    wire([(510, s_echo), (node_x, s_echo), (node_x, ye), (pin_x, ye)], SIG)
    dot(node_x, ye)
    add(f'<rect x="{node_x - 6}" y="{ye + 14}" width="12" height="40" fill="#d7ccc8" stroke="#333"/>')
    label(node_x + 10, ye + 40, "2 kΩ", "start", "#000", 11)
    wire([(node_x, ye), (node_x, ye + 14)], SIG)
    wire([(node_x, ye + 54), (node_x, ye + 66), (rail_x, ye + 66)], BLK)
    dot(rail_x, ye + 66)
    label(node_x - 8, ye - 8, f"{echo_volts():.2f} V", "end", SIG, 11)
    wire([(sx, s_gnd), (545, s_gnd), (545, 520), (rail_x, 520)], BLK)
    # --- Arduino, ESC, servo (grounds drawn as ground symbols: all of them are joined)
    def ground(x, y):
        wire([(x, y), (x, y + 12)], BLK)
        for i, half in enumerate((10, 6, 2)):
            add(f'<line x1="{x - half}" y1="{y + 12 + i * 4}" x2="{x + half}" y2="{y + 12 + i * 4}" stroke="{BLK}" stroke-width="2"/>')

    ax, ay, aw, ah = 760, 80, 200, 150
    box(ax, ay, aw, ah, "Arduino Uno", "#e0f7fa")
    label(ax + 100, ay + 40, "firmware/rccar_fw", "middle", "#555", 11)
    d9, d10, agnd = ax + 30, ax + 140, ax + 180
    for x, n in ((d9, "D9"), (d10, "D10"), (agnd, "GND")):
        add(f'<rect x="{x - 9}" y="{ay + ah - 9}" width="18" height="18" fill="#ffd54f" stroke="#333"/>')
        label(x, ay + ah - 16, n, "middle", "#000", 11)
    add(f'<rect x="{ax - 10}" y="{ay + 60}" width="50" height="26" rx="4" fill="#ccc" stroke="#333"/>')
    label(ax + 15, ay + 78, "USB", "middle")
    ground(agnd, ay + ah + 9)
    wire([(px + 180, py + 443), (px + 230, py + 443), (px + 230, 600), (740, 600), (740, ay + 73), (ax - 10, ay + 73)], USB)
    label(480, 594, "USB cable: power + serial (/dev/ttyACM0)", "middle", USB, 11)
    # servo: signal straight down from D9, + from the ESC's BEC, - to ground
    vx, vy = 770, 330
    box(vx, vy, 95, 100, "Servo", "#ede7f6")
    label(vx + 47, vy + 42, "steering", "middle", "#555", 10)
    wire([(d9, ay + ah + 9), (d9, vy)], SIG)
    label(d9 + 6, vy - 50, "signal", "start", SIG, 10)
    s_plus = vx + 55
    ground(vx + 80, vy + 100)
    # ESC: signal straight down from D10, BEC + over to the servo's +, - to ground
    ex, ey = 880, 330
    box(ex, ey, 95, 100, "ESC", "#fce4ec")
    label(ex + 47, ey + 42, "motor,", "middle", "#555", 10)
    label(ex + 47, ey + 56, "drive battery", "middle", "#555", 10)
    wire([(d10, ay + ah + 9), (d10, ey)], SIG)
    e_plus = ex + 12
    wire([(e_plus, ey), (e_plus, ey - 30), (s_plus, ey - 30), (s_plus, vy)], RED)
    label((e_plus + s_plus) / 2, ey - 36, "BEC +", "middle", RED, 10)
    ground(ex + 80, ey + 100)
    # legend
    items = ((RED, "5 V: Pi 5V to HC-SR04; the ESC's BEC (5-6 V) to the servo"),
             (BLK, "ground: one common ground (Pi, Arduino, ESC, servo, sensor)"),
             (SIG, "signal"), (USB, "USB"))
    for i, (c, n) in enumerate(items):
        y = 480 + i * 20
        wire([(560, y), (590, y)], c)
        label(598, y + 4, n, "start", "#000", 11)
    add("</svg>")
    return "\n".join(o) + "\n"


def main(argv):
    p, from_config = pins()
    if "--table" in argv:
        print(table(p, from_config))
        return 0
    text = svg(p, from_config)
    if "--check" in argv:
        old = OUT.read_text(encoding="utf-8") if OUT.exists() else ""
        if old != text:
            print(f"{OUT.relative_to(ROOT)} is out of date with config/car.toml: run python3 docs/img/wiring.py")
            return 1
        print(f"{OUT.relative_to(ROOT)} matches config/car.toml")
        return 0
    OUT.write_text(text, encoding="utf-8")
    print(f"wrote {OUT.relative_to(ROOT)} (pins {p}, {'from config' if from_config else 'defaults'})")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))

#!/usr/bin/env python3
"""Seed the fuzz corpora with the examples from ../PROTOCOL.md (run from this folder).

The binary frames carry a CRC and the sentences an XOR checksum, which random mutation rarely
gets right; starting from valid messages lets libFuzzer reach the payload decoders at once.
"""
import os, re

here = os.path.dirname(os.path.abspath(__file__))
doc = open(os.path.join(here, "..", "PROTOCOL.md")).read()
examples = []
for kind, name, body in re.findall(r"```(hex|nmea) (\S+)\n(.*?)```", doc, re.S):
    if kind == "hex":
        examples.append((name, bytes.fromhex(body.replace("\n", " "))))
    else:
        examples.append((name, body.strip().encode() + b"\r\n"))

def put(target, name, data):
    d = os.path.join(here, "corpus", target)
    os.makedirs(d, exist_ok=True)
    with open(os.path.join(d, "seed-" + name), "wb") as f:
        f.write(data)

everything = b"".join(data for _, data in examples)
for name, data in examples:
    put("line_decoder", name, bytes([3]) + b"\x00junk" + data)
    if data[:1] == b"$":
        put("nmea_line", name, data)
        put("nmea_fields", name, data[1:data.index(b"*")])
    elif data[:1] == b"@":
        put("sonar_command", name, data)
    else:
        put("sensor_frame", name, data)
        put("sensor_message", name, data[2:4] + data[5:-2])
put("line_decoder", "all-examples", bytes([7]) + everything)
print(f"{len(examples)} examples seeded")

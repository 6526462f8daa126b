#!/usr/bin/env python3
"""Converts the DeepMind ball states (rallies.json, serves.json) into the
compact CSV that topspin_sim::strokes embeds: the same entries in the same
frame, one row each, values rounded to 7 significant digits (the data are
float32). Usage: tools/human_strokes_csv.py SRC_DIR > crates/sim/data/human-strokes/states.csv
"""
import json
import sys

FIELDS = ["pos_x", "pos_y", "pos_z", "vel_x", "vel_y", "vel_z", "w_vel_x", "w_vel_y", "w_vel_z"]


def main(src):
    print("kind,id," + ",".join(FIELDS))
    for kind, name in (("rally", "rallies.json"), ("serve", "serves.json")):
        with open(f"{src}/{name}") as f:
            for e in json.load(f):
                print(f"{kind},{e['id']}," + ",".join("%.7g" % e[k] for k in FIELDS))


if __name__ == "__main__":
    main(sys.argv[1])

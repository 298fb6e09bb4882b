"""Compares what seabus (`seabus spy --n2k --json`) and canboat's analyzer (`analyzer -json
-camel`) decoded from the same NMEA 2000 frames, PGN by PGN, field by field, after the unit forms
docs/nmea2000.md gives: dates (the analyzer's `YYYY.MM.DD`, seabus's days since 1970), times of day
(`HH:MM:SS.ffff`, seconds), binary fields (hex, bytes), numbers within the last digit the analyzer
prints.

Lookup names: where the analyzer's own tables (its `lookup-generated-data.h`) name a value
differently from the canboat database seabus follows (`canboat.json`), seabus's is the database's;
the renames are read from both files, never written here.

Usage: n2k_compare.py ANALYZER_OUT SEABUS_OUT ANALYZER_LOOKUPS_H CANBOAT_JSON
Prints one JSON object: {"compared": N, "pgns": {...count per id...}, "differences": [...], "only":
{...}, "unknown": [...]} where `only` counts messages one side decoded and the other did not, per
id, and `unknown` lists the PGNs seabus published by number (no definition of its own).
"""
import base64
import datetime
import json
import re
import sys
from collections import defaultdict

RENAMES = {}


def renames(header, database):
    """Analyzer name -> database name, for the values both name differently."""
    ours = {}
    for line in open(header):
        m = re.match(r'^LOOKUP\((\w+), (\d+), "(.*)"\)$', line.strip())
        if m:
            ours[(m.group(1), int(m.group(2)))] = m.group(3)
        m = re.match(r'^LOOKUP_TRIPLET\((\w+), (\d+), (\d+), "(.*)"\)$', line.strip())
        if m:
            ours[(m.group(1), int(m.group(2)), int(m.group(3)))] = m.group(4)
    db = json.load(open(database))
    out = {}
    for e in db["LookupEnumerations"]:
        for v in e["EnumValues"]:
            a = ours.get((e["Name"], v["Value"]))
            if a is not None and a != v["Name"]:
                out[a] = v["Name"]
    for e in db["LookupIndirectEnumerations"]:
        for v in e["EnumValues"]:
            a = ours.get((e["Name"], v["Value1"], v["Value2"]))
            if a is not None and a != v["Name"]:
                out[a] = v["Name"]
    return out


def analyzer(path):
    out = []
    for line in open(path):
        j = json.loads(line)
        for key, m in j.items():
            if isinstance(m, dict) and "pgn" in m:
                out.append((m["pgn"], m["src"], m["dst"], key, m.get("fields", {})))
    return out


def seabus(path):
    out = []
    for line in open(path):
        m = json.loads(line)
        if "pgn" in m and "fields" in m:
            out.append((m["pgn"], m["src"], m["dst"], m["id"], m["fields"], m.get("units", {})))
    return out


def decimals(text):
    text = str(text)
    return len(text.split(".")[1]) if "." in text else 0


# what the analyzer prints in another unit than seabus: seabus's unit -> the factor from the
# analyzer's (bar, ampere-hours)
FACTORS = {"Pa": 100000.0, "C": 3600.0}


def same(a, s, raw, factor):
    """Whether the analyzer's value `a` (`raw` its JSON text, `factor` to seabus's unit) is
    seabus's `s`."""
    if isinstance(a, str):
        if isinstance(s, (int, float)) and not isinstance(s, bool):
            if len(a) == 10 and a[4] == "." and a[7] == ".":
                day = datetime.date(int(a[:4]), int(a[5:7]), int(a[8:]))
                return (day - datetime.date(1970, 1, 1)).days == s
            if len(a) >= 8 and a[2] == ":" and a[5] == ":":
                h, m, sec = a.split(":")
                return abs(int(h) * 3600 + int(m) * 60 + float(sec) - s) <= 10 ** -decimals(sec)
            return False
        if isinstance(s, dict) and "base64" in s:
            return bytes.fromhex(a.replace(" ", "")) == base64.b64decode(s["base64"])
        return a.strip() == str(s).strip() or RENAMES.get(a) == s
    if isinstance(a, bool) or isinstance(s, bool):
        return a == s
    if isinstance(a, (int, float)):
        if not isinstance(s, (int, float)):
            return False
        return abs(a * factor - s) <= (10 ** -decimals(raw) * 1.0001 + 1e-12) * factor
    if isinstance(a, list):
        if not isinstance(s, list):
            return False
        # a repeating set the analyzer prints with nothing in it is no set
        a = [x for x in a if x != {}]
        return len(a) == len(s) and all(fields_same(x, y, {}) is None for x, y in zip(a, s))
    return a == s


def fields_same(a, s, units):
    """None when the analyzer's fields `a` are seabus's `s` (docs/nmea2000.md's forms: reserved
    and spare fields are not given), else what differs."""
    if not isinstance(s, dict):
        return {"analyzer": a, "seabus": s}
    a = {k: v for k, v in a.items() if not k.startswith(("reserved", "spare"))}
    diff = {}
    for k in sorted(set(a) | set(s)):
        if k not in s:
            diff[k] = {"analyzer": a[k], "seabus": None}
        elif k not in a:
            diff[k] = {"analyzer": None, "seabus": s[k]}
        elif not same(a[k], s[k], json.dumps(a[k]), FACTORS.get(units.get(k), 1.0)):
            diff[k] = {"analyzer": a[k], "seabus": s[k]}
    return diff or None


def main():
    RENAMES.update(renames(sys.argv[3], sys.argv[4]))
    a_list, s_list = analyzer(sys.argv[1]), seabus(sys.argv[2])
    # the PGNs seabus has no definition of: published by number, not decoded
    unknown = sorted({m[0] for m in s_list if m[3] == str(m[0])})
    by = defaultdict(lambda: ([], []))
    for m in a_list:
        if m[0] not in unknown:
            by[(m[0], m[1], m[2], m[3])][0].append(m)
    for m in s_list:
        if m[0] not in unknown:
            by[(m[0], m[1], m[2], m[3])][1].append(m)
    compared, pgns, differences, only = 0, defaultdict(int), [], defaultdict(int)
    for key, (ams, sms) in sorted(by.items()):
        # in order; a message one side has and the other not (the analyzer refuses some) is
        # passed over when the next ones agree
        j = 0
        for i, am in enumerate(ams):
            ahead = next((k for k in range(j, len(sms))
                          if fields_same(am[4], sms[k][4], sms[k][5]) is None), None)
            if ahead is None and j < len(sms):
                # seabus's next one is a later message of the analyzer's: this one seabus has not
                later = any(fields_same(x[4], sms[j][4], sms[j][5]) is None for x in ams[i + 1:])
                ahead = None if later else j
            if ahead is None:
                only["analyzer:" + am[3]] += 1
                continue
            only["seabus:" + am[3]] += ahead - j
            sm = sms[ahead]
            j = ahead + 1
            compared += 1
            pgns[am[3]] += 1
            d = fields_same(am[4], sm[4], sm[5])
            if d:
                differences.append({"pgn": key[0], "src": key[1], "id": am[3], "diff": d})
        only["seabus:" + key[3]] += len(sms) - j
    only = {k: v for k, v in only.items() if v}
    print(json.dumps({"compared": compared, "pgns": pgns, "differences": differences,
                      "only": only, "unknown": unknown, "renames": len(RENAMES)}))


main()

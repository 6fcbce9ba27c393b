#!/usr/bin/python3
"""Validates payloads (one JSON document per line of FILE) against SCHEMA with
python3-jsonschema (Debian).  Prints one line per invalid payload; exit 1 if any."""
import json
import sys

import jsonschema


def main():
    schema_file, payload_file = sys.argv[1], sys.argv[2]
    with open(schema_file, encoding="utf-8") as f:
        schema = json.load(f)
    jsonschema.Draft7Validator.check_schema(schema)
    validator = jsonschema.Draft7Validator(schema)
    bad = 0
    count = 0
    with open(payload_file, encoding="utf-8") as f:
        for n, line in enumerate(f, 1):
            line = line.rstrip("\n")
            if not line:
                continue
            count += 1
            try:
                doc = json.loads(line)
            except json.JSONDecodeError as e:
                print(f"payload {n}: not JSON: {e}: {line[:200]}")
                bad += 1
                continue
            errors = sorted(validator.iter_errors(doc), key=lambda e: list(e.path))
            if errors:
                bad += 1
                print(f"payload {n}: {errors[0].message} at {list(errors[0].path)}: {line[:300]}")
    print(f"validated {count} payloads, {bad} invalid")
    sys.exit(1 if bad else 0)


if __name__ == "__main__":
    main()

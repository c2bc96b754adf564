"""JSON files the bench scripts share: read leniently, written atomically (temp file + rename), so a
killed script never leaves a half-written record that looks complete."""
import json
import os


def read_json(path):
    """The parsed file, or None when it is missing or not JSON."""
    try:
        with open(path) as fh:
            return json.load(fh)
    except (OSError, ValueError):
        return None


def write_json(path, obj):
    tmp = path + ".tmp"
    with open(tmp, "w") as fh:
        json.dump(obj, fh, indent=2)
        fh.write("\n")
    os.replace(tmp, path)

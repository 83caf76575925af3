#!/usr/bin/env python3
"""Loads every YAML manifest under docs/jobs/ (PyYAML) and checks that no image is a placeholder:
each container names `seasonstereo` (set by kustomization.yaml) or a real tool image."""
import glob
import sys

import yaml

bad = 0
for path in sorted(glob.glob("docs/jobs/*.yaml")):
    for doc in yaml.safe_load_all(open(path)):
        text = yaml.safe_dump(doc or {})
        if "example/" in text:
            print(f"{path}: a placeholder image name; use `seasonstereo` (kustomization.yaml)")
            bad += 1
    print(f"{path}: OK")
sys.exit(1 if bad else 0)

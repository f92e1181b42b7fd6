#!/usr/bin/env python3
"""Checks the real charts of MANIFEST.tsv with `skillpost --sfc` (docs/REAL-CHARTS.md).

    python3 bench/realcharts/check.py --fetch DIR    # clone each repository, take each file at
                                                     # its commit into DIR (needs network, git)
    python3 bench/realcharts/check.py DIR [--bin target/debug/skillpost]

DIR holds the files as `<owner>+<repo>/<path with / as __>`. Every POU and POU action with an SFC
body is run as `skillpost --sfc --pou NAME FILE`; a chart is the same name with the same SFC XML
(counted once, however many files hold it). Prints one line per distinct chart that fails, with
its first error, and the totals (all charts, and those outside VerifAPS/verifaps-lib). Exit 0.
"""
import argparse
import csv
import hashlib
import os
import re
import subprocess
import sys
import tempfile
import xml.etree.ElementTree as ET

HERE = os.path.dirname(os.path.abspath(__file__))
MANIFEST = os.path.join(HERE, 'MANIFEST.tsv')


def rows():
    """The MANIFEST's lines, each with `local_file`: `<owner>+<repo>/<path, / as __>`."""
    with open(MANIFEST, newline='') as f:
        for r in csv.DictReader(f, delimiter='\t'):
            r['local_file'] = f"{r['repo'].replace('/', '+')}/{r['path'].replace('/', '__')}"
            yield r


def fetch(into):
    by_repo = {}
    for r in rows():
        by_repo.setdefault(r['repo'], []).append(r)
    with tempfile.TemporaryDirectory() as tmp:
        for repo, files in sorted(by_repo.items()):
            clone = os.path.join(tmp, repo.replace('/', '+'))
            subprocess.run(['git', 'clone', '--quiet', '--bare', '--filter=blob:none',
                            f'https://github.com/{repo}', clone], check=True)
            for r in files:
                out = os.path.join(into, r['local_file'])
                os.makedirs(os.path.dirname(out), exist_ok=True)
                data = subprocess.run(['git', f'--git-dir={clone}', 'show',
                                       f"{r['commit']}:{r['path']}"],
                                      check=True, capture_output=True).stdout
                with open(out, 'wb') as f:
                    f.write(data)
            print(f'{repo}: {len(files)} files', file=sys.stderr)


def local(tag):
    return tag.rsplit('}', 1)[-1]


def charts(data):
    """(name for --pou, hash of the SFC XML) of every POU body and POU action that is an SFC."""
    out = []
    root = ET.fromstring(data)
    for pou in root.iter():
        if local(pou.tag) != 'pou':
            continue
        name = pou.get('name')
        for body in (c for c in pou if local(c.tag) == 'body'):
            for sfc in (g for g in body if local(g.tag) == 'SFC'):
                out.append((name, hashlib.sha1(ET.tostring(sfc)).hexdigest()))
        for action in pou.iter():
            if local(action.tag) != 'action' or not action.get('name'):
                continue
            for body in (c for c in action if local(c.tag) == 'body'):
                for sfc in (g for g in body if local(g.tag) == 'SFC'):
                    out.append((f"{name}.{action.get('name')}",
                                hashlib.sha1(ET.tostring(sfc)).hexdigest()))
    return out


def check(files, binary):
    seen = {}
    for r in rows():
        path = os.path.join(files, r['local_file'])
        if not os.path.exists(path):
            print(f"missing: {path} ({r['repo']} {r['path']})", file=sys.stderr)
            continue
        try:
            found = charts(open(path, 'rb').read())
        except ET.ParseError as e:
            print(f"not XML: {path}: {e}", file=sys.stderr)
            continue
        for name, digest in found:
            if (name, digest) in seen:
                continue
            p = subprocess.run([binary, '--sfc', '--format', 'short', '--pou', name, path],
                               capture_output=True, text=True, timeout=300)
            first = next((l for l in (p.stderr + p.stdout).splitlines() if 'error[' in l), '')
            seen[(name, digest)] = (r['repo'], r['path'], p.returncode == 0, first)
    fails = [(k, v) for k, v in seen.items() if not v[2]]
    for (name, _), (repo, path, _, first) in sorted(fails, key=lambda kv: kv[1][:2]):
        first = re.sub(r'^.*?(error\[)', r'\1', first)
        print(f'{repo} {path} --pou {name}: {first}')
    outside = {k: v for k, v in seen.items() if v[0] != 'VerifAPS/verifaps-lib'}
    print(f'{len(seen)} distinct charts: {len(seen) - len(fails)} pass, {len(fails)} fail')
    print(f'outside VerifAPS/verifaps-lib: {len(outside)} charts, '
          f'{sum(1 for v in outside.values() if v[2])} pass')


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('dir')
    ap.add_argument('--fetch', action='store_true', help='fetch the files into DIR first')
    ap.add_argument('--bin', default=os.path.join(HERE, '..', '..', 'target', 'debug', 'skillpost'))
    a = ap.parse_args()
    if a.fetch:
        fetch(a.dir)
    check(a.dir, a.bin)


if __name__ == '__main__':
    main()

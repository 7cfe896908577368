#!/usr/bin/env python3
"""Measures `flankcam verify` on hand-edited programs: every bundled example on every shipped machine
and every dialect the machine takes is run (`flankcam run`); every program is verified as written (it
must be clean: exit 0) and as copies with the Z of one cutting block lowered by 1 mm (at 25 %, 50 % and
75 % of its feed blocks, each copy separately): each copy must be refused naming that line.

  python3 bench/verify_edits.py build/cli/flankcam OUT_DIR [--examples a,b] [--machines m1,m2]

Prints one line per machine x dialect x example and the totals. Runs fit + post for every case, so
it takes minutes on 2 cores."""
import os, re, subprocess, sys, yaml

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
EXAMPLES = ["conical-tool/job.yaml", "blade/job-1-patch.yaml", "blade/job-3-patches.yaml",
            "exact-envelope/job.yaml", "auto/job.yaml"]
MACHINES = ["xyzac-trt", "xyzbc-trt", "xyzbc-head-table", "xyzca-head-head", "xyzbc-nutating"]
DIALECTS = ["iso", "linuxcnc", "heidenhain", "sinumerik"]
EXT = {"iso": ".nc", "linuxcnc": ".ngc", "heidenhain": ".h", "sinumerik": ".mpf"}


def feed_lines(lines, dialect):
    """Indices of the feed (cutting) blocks that state Z."""
    out, motion = [], None
    for i, l in enumerate(lines):
        code = re.sub(r"\(.*?\)", "", l).split(";")[0].upper()
        if dialect == "heidenhain":
            if re.match(r"\s*\d+\s+L\s", code) and "FMAX" not in code and re.search(r"\bZ[+-]", code):
                out.append(i)
            continue
        for g in re.findall(r"\bG0*([01])\b", code):
            motion = g
        if motion == "1" and re.search(r"\bZ=?-?[0-9.]", code):
            out.append(i)
    return out


def lower_z(line, dialect):
    if dialect == "heidenhain":
        return re.sub(r"\bZ([+-][0-9.]+)", lambda m: "Z%+.4f" % (float(m.group(1)) - 1), line, count=1)
    return re.sub(r"\bZ(=?)(-?[0-9.]+)", lambda m: "Z%s%.4f" % (m.group(1), float(m.group(2)) - 1), line, count=1)


def main():
    flankcam, out_root = os.path.abspath(sys.argv[1]), os.path.abspath(sys.argv[2])
    args = dict(a.split("=", 1) for a in sys.argv[3:] if "=" in a)
    examples = args.get("--examples", ",".join(EXAMPLES)).split(",")
    machines = args.get("--machines", ",".join(MACHINES)).split(",")
    os.makedirs(out_root, exist_ok=True)
    totals = {}
    for machine in machines:
        for dialect in DIALECTS:
            for ex in examples:
                job_path = os.path.join(ROOT, "examples", ex)
                job = yaml.safe_load(open(job_path))
                base = os.path.dirname(job_path)
                job["surface"] = os.path.normpath(os.path.join(base, job["surface"]))
                if "part" in job:
                    job["part"] = os.path.normpath(os.path.join(base, job["part"]))
                job["machine"] = machine
                job.setdefault("post", {})["dialects"] = [dialect]
                case = "%s-%s-%s" % (machine, dialect, ex.replace("/", "-").replace(".yaml", ""))
                d = os.path.join(out_root, case)
                os.makedirs(d, exist_ok=True)
                jf = os.path.join(d, "job.yaml")
                yaml.safe_dump(job, open(jf, "w"))
                run = subprocess.run([flankcam, "run", jf, "--quiet", "--out", os.path.join(d, "run")],
                                     capture_output=True, text=True)
                if run.returncode != 0:
                    print("%-55s run exit %d: %s" % (case, run.returncode, run.stderr.strip().splitlines()[-1][:100]))
                    continue
                rd = os.path.join(d, "run")
                programs = sorted(f for f in os.listdir(rd) if f.endswith(EXT[dialect]))
                v = subprocess.run([flankcam, "verify", "--job", jf, "--out", os.path.join(d, "v0")] +
                                   [os.path.join(rd, p) for p in programs], capture_output=True, text=True)
                false_alarms = [l for l in v.stdout.splitlines() if ": clean" not in l]
                copies = {}
                for p in programs:
                    lines = open(os.path.join(rd, p)).read().split("\n")
                    feeds = feed_lines(lines, dialect)
                    for q in (25, 50, 75):
                        i = feeds[len(feeds) * q // 100]
                        edited = list(lines)
                        edited[i] = lower_z(lines[i], dialect)
                        assert edited[i] != lines[i], (p, lines[i])
                        name = p.replace(EXT[dialect], "-z%d%s" % (q, EXT[dialect]))
                        open(os.path.join(rd, name), "w").write("\n".join(edited))
                        copies[name] = i + 1
                e = subprocess.run([flankcam, "verify", "--job", jf, "--out", os.path.join(d, "v1")] +
                                   [os.path.join(rd, c) for c in copies], capture_output=True, text=True)
                caught = sum(1 for c, line in copies.items()
                             if re.search(re.escape(os.path.join(rd, c)) + ":%d:" % line, e.stdout))
                named_other = sum(1 for c in copies if re.search(re.escape(os.path.join(rd, c)) + r":\d+:", e.stdout)) - caught
                t = totals.setdefault((machine, dialect), [0, 0, 0, 0, 0])
                t[0] += len(programs); t[1] += len(false_alarms); t[2] += len(copies); t[3] += caught; t[4] += named_other
                print("%-55s programs %2d clean %2d (exit %d) | edited %2d caught %2d other line %d (exit %d)" % (
                    case, len(programs), len(programs) - len(false_alarms), v.returncode, len(copies), caught,
                    named_other, e.returncode))
                for l in false_alarms:
                    print("    false alarm:", l[:200])
                sys.stdout.flush()
    print("\nmachine            dialect     programs  false alarms  edited  caught (named the line)")
    for (m, dl), t in totals.items():
        print("%-18s %-11s %8d  %12d  %6d  %6d" % (m, dl, t[0], t[1], t[2], t[3]))
    s = [sum(t[k] for t in totals.values()) for k in range(5)]
    print("%-30s %8d  %12d  %6d  %6d" % ("all", s[0], s[1], s[2], s[3]))


main()

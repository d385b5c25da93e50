#!/usr/bin/python3
"""Per-stage cost of a training iteration (docs/benchmarks.md, "Training iteration: profile by stage").

  tools/train_stages.py callgrind ITERATIONS FILE...   inclusive instruction counts of `callgrind_annotate`
                                                        (the files of one run, e.g. a partial dump and the final one, are summed)
  tools/train_stages.py perf ITERATIONS FILE           CPU time from `perf report --children --sort symbol --stdio -g none`
                                                        of a `perf record -e cpu-clock --call-graph dwarf` run

Both measure `Trainer::step()` (the PLY save at a run's last iteration excluded) and split it by the functions
of each stage; "everything else" is the rest of step() (finite checks, clamps, copies, the NDC gradient).
"""
import re
import subprocess
import sys

# Function names without return type, parameters and "(anonymous namespace)::" (name() below).
STAGES = [
    ('dropout mask (DD-Drop)', r'D2gs::opacity_multiplier$'),
    ('projection', r'^d2gs::render::cpu::project_forward<float>$'),
    ('SH', r'^d2gs::render::cpu::sh_forward<float>$'),
    ('binning', r'^d2gs::render::cpu::bin_gaussians<float>$'),
    ('compositing forward', r'^d2gs::render::cpu::composite_forward<float>$'),
    ('L1', r'^d2gs::l1_loss$'),
    ('SSIM forward + backward', r'^d2gs::Ssim<float>::evaluate$'),
    ('DAFE', r'^d2gs::dafe_loss$'),
    ('compositing backward', r'^d2gs::render::cpu::composite_backward<float>$'),
    ('projection backward', r'^d2gs::render::cpu::project_backward<float>$'),
    ('SH backward', r'^d2gs::render::cpu::sh_backward<float>$'),
    ('densification statistics', r'^d2gs::GradientStats::add$'),
    ('Adam', r'^d2gs::Adam::step$'),
]
STEP = r'^d2gs::Trainer::step$'
SAVE = r'^d2gs::write_gaussians_ply$'


def name(symbol):
    s = symbol.replace('(anonymous namespace)::', '').strip()
    suffix = ' [omp]' if '_omp_fn' in s else ''
    if ' [clone' in s:
        s = s[:s.index(' [clone')]
    s = re.sub(r'^(void|bool|float|double|int) ', '', s)
    return s.split('(')[0].strip() + suffix


def find(costs, pattern):
    hits = [v for k, v in costs.items() if re.search(pattern, k)]
    return max(hits) if hits else 0.0


def callgrind(files):
    costs = {}
    for f in files:
        out = subprocess.run(['callgrind_annotate', '--inclusive=yes', '--threshold=100', f],
                             capture_output=True, text=True, check=True).stdout
        in_file = {}
        for line in out.splitlines():
            m = re.match(r'\s*([\d,]+)\s+\([\s\d.]+%\)\s+\S*?:(.*?)( \[/[^]]*\])?$', line)
            if m:
                key = name(m.group(2))
                in_file[key] = max(in_file.get(key, 0), int(m.group(1).replace(',', '')))
        for key, v in in_file.items():
            costs[key] = costs.get(key, 0) + v
    return costs


def perf(file):
    # cpu-clock's event count is nanoseconds of CPU time.
    costs, total_ns = {}, 0.0
    for line in open(file):
        m = re.match(r'# Event count \(approx.\): (\d+)', line)
        if m:
            total_ns = float(m.group(1))
        m = re.match(r'\s+([\d.]+)%\s+([\d.]+)%\s+\[\.\]\s+(.*?)\s+-\s+-\s*$', line) or \
            re.match(r'\s+([\d.]+)%\s+([\d.]+)%\s+\[\.\]\s+(.*?)\s*$', line)
        if m:
            key = name(m.group(3))
            costs[key] = max(costs.get(key, 0.0), float(m.group(1)) * total_ns / 100)
    return costs


def main():
    mode, iterations = sys.argv[1], int(sys.argv[2])
    if mode == 'callgrind':
        costs, unit, scale = callgrind(sys.argv[3:]), 'M instructions', 1e-6
    else:
        costs, unit, scale = perf(sys.argv[3]), 'ms', 1e-6
    step = find(costs, STEP) - find(costs, SAVE)
    print(f'| stage | {unit} per iteration | share |')
    print('|---|---|---|')
    total = 0.0
    for name, pattern in STAGES:
        v = find(costs, pattern)
        total += v
        print(f'| {name} | {v * scale / iterations:.1f} | {100 * v / step:.1f} % |')
    print(f'| everything else | {(step - total) * scale / iterations:.1f} | {100 * (step - total) / step:.1f} % |')
    print(f'| **whole iteration** | **{step * scale / iterations:.1f}** | 100 % |')


if __name__ == '__main__':
    main()

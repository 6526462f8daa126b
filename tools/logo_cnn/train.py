#!/usr/bin/env python3
"""Trains the logo CNN of the paper's §III and exports it to ONNX.

The network sees one 60x60 RGB crop of the ball (cut by the camera side
around the measured circle, as TTI1 carries it) and predicts

* the logo's visibility (is the logo's centre on the hemisphere facing the
  camera?), and
* the ball's orientation as a unit quaternion.

The logo is a circle, so the ball's twist about the logo's axis cannot be
seen: the target quaternion is the *swing* that turns the view frame's +z
(towards the camera; x along image u, y image up, see src/logo/view.rs)
onto the logo's centre, q = normalise(1 + z, -y, x, 0). The logo direction
is then q * e_z * q^-1, and the paper's metrics are well defined: geodesic
angle between quaternions (sign-aware) and the angle between the logo
vectors. Labels come from `topspin render` (column view_x, view_y, view_z).

The loss is the paper's conditional loss: binary cross-entropy on the
visibility, plus the orientation term (sign-aware L1 or L2 on the
quaternion, or the geodesic angle) only where the logo is visible.
Augmentation as in the paper: random multiples of 90 deg (the target turned
with the image) and 5 % Gaussian noise; `--jitter` adds a brightness and
colour jitter on top (ours, for other lighting).

Exported graph: input `crops` float32 [N, 3, 60, 60] in [0, 1] (RGB),
outputs `visibility` [N] (probability) and `quaternion` [N, 4] (w, x, y, z;
unit). Single file (no external data). Seeded; writes METRICS JSON.

Usage (from the repository root; see tools/logo_cnn/README.md):
    python tools/logo_cnn/train.py --data DATA --arch compact --epochs 30 \
        --out models/logo-compact.onnx --metrics models/logo-compact.json
"""

import argparse
import csv
import json
import math
import os
import random
import time

import numpy as np
import torch
import torch.nn as nn
import torch.nn.functional as F
from PIL import Image

CROP = 60


# --------------------------------------------------------------------- data


def load_dir(d):
    """All crops of one `topspin render --out` folder."""
    images, vis, logo, keys, colours = [], [], [], [], []
    with open(os.path.join(d, "labels.csv"), newline="") as f:
        for row in csv.DictReader(f):
            v = np.array([float(row["view_x"]), float(row["view_y"]), float(row["view_z"])])
            if not np.all(np.isfinite(v)):
                continue
            img = np.asarray(Image.open(os.path.join(d, row["file"])).convert("RGB"), dtype=np.uint8)
            if img.shape != (CROP, CROP, 3):
                continue
            images.append(img)
            v = v / np.linalg.norm(v)
            logo.append(v)
            vis.append(1.0 if v[2] > 0.0 else 0.0)
            keys.append(f"{os.path.basename(d)}/{row['ball']}")
            colours.append(row["colour"])
    return images, vis, logo, keys, colours


def load(dirs):
    out = ([], [], [], [], [])
    for d in dirs:
        for acc, part in zip(out, load_dir(d)):
            acc.extend(part)
    images, vis, logo, keys, colours = out
    return {
        "x": np.stack(images),
        "vis": np.array(vis, dtype=np.float32),
        "logo": np.array(logo, dtype=np.float32),
        "key": np.array(keys),
        "colour": np.array(colours),
    }


def subset(d, mask):
    return {k: v[mask] for k, v in d.items()}


def split_by_ball(d, test_share=0.2, seed=0):
    """A fixed 4:1 split by ball (frames of one ball never straddle it)."""
    balls = sorted(set(d["key"].tolist()))
    rng = random.Random(seed)
    rng.shuffle(balls)
    test = set(balls[: int(round(test_share * len(balls)))])
    mask = np.array([k in test for k in d["key"]])
    return subset(d, ~mask), subset(d, mask)


def swing_quaternion(logo):
    """q = normalise(1 + z, -y, x, 0): +z onto the logo (w, x, y, z)."""
    x, y, z = logo[:, 0], logo[:, 1], logo[:, 2]
    q = np.stack([1.0 + z, -y, x, np.zeros_like(z)], axis=1)
    n = np.linalg.norm(q, axis=1, keepdims=True)
    q = np.where(n > 1e-6, q / np.maximum(n, 1e-6), np.array([[0.0, 1.0, 0.0, 0.0]]))
    return q.astype(np.float32)


def logo_of(q):
    """The logo direction q e_z q^-1 for unit quaternions (w, x, y, z)."""
    w, x, y, z = q.unbind(-1)
    return torch.stack([2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)], dim=-1)


def augment(x, logo, rng, jitter):
    """Random 90 deg turns (target turned with the image), noise, jitter.

    x: float [B, 3, H, W] in [0, 1]; logo: [B, 3] in the view frame. A turn
    of the image by +90 deg (counter-clockwise as seen, np.rot90) maps the
    view frame's (x, y) to (-y, x).
    """
    k = int(rng.integers(0, 4))
    if k:
        x = torch.rot90(x, k, dims=(2, 3))
        for _ in range(k):
            logo = torch.stack([-logo[:, 1], logo[:, 0], logo[:, 2]], dim=1)
    if jitter:
        b = x.shape[0]
        gain = torch.from_numpy(rng.uniform(0.75, 1.25, size=(b, 1, 1, 1)).astype(np.float32))
        tint = torch.from_numpy(rng.uniform(0.9, 1.1, size=(b, 3, 1, 1)).astype(np.float32))
        x = (x * gain * tint).clamp(0.0, 1.0)
    x = x + 0.05 * torch.from_numpy(rng.standard_normal(size=x.shape).astype(np.float32))
    return x, logo


# ------------------------------------------------------------------- models


class Head(nn.Module):
    """Wraps a body: normalised input, then visibility and unit quaternion."""

    def __init__(self, body):
        super().__init__()
        self.body = body

    def raw(self, x):
        return self.body((x - 0.5) / 0.25)

    def forward(self, x):
        out = self.raw(x)
        vis = torch.sigmoid(out[:, 0])
        q = out[:, 1:5]
        q = q / torch.sqrt((q * q).sum(dim=1, keepdim=True) + 1e-12)
        return vis, q


class BasicBlock(nn.Module):
    def __init__(self, cin, cout, stride):
        super().__init__()
        self.c1 = nn.Conv2d(cin, cout, 3, stride, 1, bias=False)
        self.b1 = nn.BatchNorm2d(cout)
        self.c2 = nn.Conv2d(cout, cout, 3, 1, 1, bias=False)
        self.b2 = nn.BatchNorm2d(cout)
        self.down = None
        if stride != 1 or cin != cout:
            self.down = nn.Sequential(nn.Conv2d(cin, cout, 1, stride, bias=False), nn.BatchNorm2d(cout))

    def forward(self, x):
        y = F.relu(self.b1(self.c1(x)))
        y = self.b2(self.c2(y))
        return F.relu(y + (x if self.down is None else self.down(x)))


class ResNet18(nn.Module):
    """The paper's network: ResNet-18, global average pooling, two fully
    connected layers of 512, then 5 outputs (visibility logit, quaternion)."""

    def __init__(self):
        super().__init__()
        self.stem = nn.Sequential(
            nn.Conv2d(3, 64, 7, 2, 3, bias=False), nn.BatchNorm2d(64), nn.ReLU(), nn.MaxPool2d(3, 2, 1)
        )
        layers, cin = [], 64
        for cout, stride in [(64, 1), (128, 2), (256, 2), (512, 2)]:
            layers += [BasicBlock(cin, cout, stride), BasicBlock(cout, cout, 1)]
            cin = cout
        self.layers = nn.Sequential(*layers)
        self.fc = nn.Sequential(nn.Linear(512, 512), nn.ReLU(), nn.Linear(512, 512), nn.ReLU(), nn.Linear(512, 5))

    def forward(self, x):
        x = self.layers(self.stem(x))
        return self.fc(x.mean(dim=(2, 3)))


def conv_bn(cin, cout, stride):
    return nn.Sequential(nn.Conv2d(cin, cout, 3, stride, 1, bias=False), nn.BatchNorm2d(cout), nn.ReLU())


class Compact(nn.Module):
    """Ours: seven 3x3 conv layers (60 -> 4 px), then the 4x4x96 map is
    flattened, not pooled, so where the logo sits on the ball stays in the
    features. About 0.4 M parameters (1.5 MB) and 15 M multiply-adds per crop."""

    def __init__(self):
        super().__init__()
        self.features = nn.Sequential(
            conv_bn(3, 16, 2),  # 30
            conv_bn(16, 24, 1),
            conv_bn(24, 32, 2),  # 15
            conv_bn(32, 48, 1),
            conv_bn(48, 64, 2),  # 8
            conv_bn(64, 96, 1),
            conv_bn(96, 96, 2),  # 4
        )
        self.fc = nn.Sequential(nn.Flatten(), nn.Linear(96 * 4 * 4, 128), nn.ReLU(), nn.Linear(128, 5))

    def forward(self, x):
        return self.fc(self.features(x))


ARCHS = {"compact": Compact, "resnet18": ResNet18}


# ------------------------------------------------------------ loss, metrics


def orientation_loss(q_hat, q, kind):
    if kind == "l1":
        return torch.minimum((q_hat - q).abs().sum(1), (q_hat + q).abs().sum(1))
    if kind == "l2":
        return torch.minimum(((q_hat - q) ** 2).sum(1), ((q_hat + q) ** 2).sum(1))
    if kind == "geodesic":
        dot = (q_hat * q).sum(1).abs().clamp(max=1.0 - 1e-6)
        return 2.0 * torch.acos(dot)
    raise ValueError(kind)


def conditional_loss(out, vis, q, kind, weight):
    """The paper's loss: visibility always, orientation only where visible."""
    bce = F.binary_cross_entropy_with_logits(out[:, 0], vis)
    q_hat = out[:, 1:5]
    q_hat = q_hat / torch.sqrt((q_hat * q_hat).sum(1, keepdim=True) + 1e-12)
    m = vis > 0.5
    if m.any():
        return bce + weight * orientation_loss(q_hat[m], q[m], kind).mean()
    return bce


@torch.no_grad()
def evaluate(model, d, batch=256):
    model.eval()
    vis_p, quats = [], []
    for i in range(0, len(d["x"]), batch):
        x = torch.from_numpy(d["x"][i : i + batch]).permute(0, 3, 1, 2).float() / 255.0
        v, q = model(x)
        vis_p.append(v)
        quats.append(q)
    vis_p = torch.cat(vis_p).numpy()
    q_hat = torch.cat(quats)
    truth_vis = d["vis"] > 0.5
    acc = float(((vis_p > 0.5) == truth_vis).mean())
    q = torch.from_numpy(swing_quaternion(d["logo"]))
    m = torch.from_numpy(truth_vis)
    geo = torch.rad2deg(2 * torch.acos((q_hat[m] * q[m]).sum(1).abs().clamp(max=1.0))).numpy()
    l_hat = logo_of(q_hat[m])
    l = torch.from_numpy(d["logo"])[m]
    vec = torch.rad2deg(torch.acos((l_hat * l).sum(1).clamp(-1.0, 1.0))).numpy()
    return {
        "crops": int(len(d["x"])),
        "logo_visible_share": float(truth_vis.mean()),
        "classification_accuracy": acc,
        "geodesic_deg_mean": float(geo.mean()),
        "geodesic_deg_median": float(np.median(geo)),
        "vector_angle_deg_mean": float(vec.mean()),
        "vector_angle_deg_median": float(np.median(vec)),
        "vector_angle_deg_p90": float(np.percentile(vec, 90)),
    }


@torch.no_grad()
def cpu_timing(model, threads=1, reps=50):
    """Median PyTorch CPU time per image and per batch of 5 (one thread)."""
    model.eval()
    old = torch.get_num_threads()
    torch.set_num_threads(threads)
    out = {}
    for n in (1, 5):
        x = torch.rand(n, 3, CROP, CROP)
        for _ in range(5):
            model(x)
        ts = []
        for _ in range(reps):
            t0 = time.perf_counter()
            model(x)
            ts.append(time.perf_counter() - t0)
        out[f"torch_ms_batch{n}"] = 1e3 * float(np.median(ts))
    torch.set_num_threads(old)
    return out


def reference_input(n=3):
    """A fixed synthetic batch the Rust tests feed both backends:
    x[b, c, i, j] = 0.5 + 0.4 sin(0.11 i + 0.17 j + 0.7 c + 1.3 b)."""
    b, c, i, j = np.meshgrid(np.arange(n), np.arange(3), np.arange(CROP), np.arange(CROP), indexing="ij")
    return (0.5 + 0.4 * np.sin(0.11 * i + 0.17 * j + 0.7 * c + 1.3 * b)).astype(np.float32)


@torch.no_grad()
def reference_outputs(model, path):
    """PyTorch's and ONNX Runtime's answers on the reference batch."""
    model.eval()
    x = reference_input()
    vis, q = model(torch.from_numpy(x))
    out = {"visibility": vis.tolist(), "quaternion": q.tolist()}
    try:
        import onnxruntime as ort

        sess = ort.InferenceSession(path, providers=["CPUExecutionProvider"])
        v2, q2 = sess.run(["visibility", "quaternion"], {"crops": x})
        out["onnxruntime_max_abs_diff"] = float(max(np.abs(v2 - vis.numpy()).max(), np.abs(q2 - q.numpy()).max()))
    except ImportError:
        pass
    return out


def export(model, path):
    model.eval()
    x = torch.rand(2, 3, CROP, CROP)
    kwargs = dict(
        input_names=["crops"],
        output_names=["visibility", "quaternion"],
        dynamic_axes={"crops": {0: "n"}, "visibility": {0: "n"}, "quaternion": {0: "n"}},
        opset_version=17,
    )
    try:
        torch.onnx.export(model, (x,), path, dynamo=False, **kwargs)
    except TypeError:
        torch.onnx.export(model, (x,), path, **kwargs)
    import onnx

    m = onnx.load(path)
    onnx.checker.check_model(m)
    onnx.save(m, path, save_as_external_data=False)


# --------------------------------------------------------------------- main


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--data", required=True, help="dataset folder from tools/logo_cnn/dataset.sh")
    p.add_argument("--arch", choices=sorted(ARCHS), default="compact")
    p.add_argument("--epochs", type=int, default=30)
    p.add_argument("--batch", type=int, default=64)
    p.add_argument("--lr", type=float, default=2e-3)
    p.add_argument("--loss", choices=["l1", "l2", "geodesic"], default="l1")
    p.add_argument("--orientation-weight", type=float, default=1.0)
    p.add_argument("--jitter", action=argparse.BooleanOptionalAction, default=True)
    p.add_argument("--seed", type=int, default=7)
    p.add_argument("--threads", type=int, default=0, help="torch threads (0: torch's choice)")
    p.add_argument("--out", required=True, help="ONNX file to write")
    p.add_argument("--metrics", required=True, help="metrics JSON to write")
    a = p.parse_args()

    torch.set_flush_denormal(True)  # 10x slower on denormals otherwise
    if a.threads:
        torch.set_num_threads(a.threads)
    random.seed(a.seed)
    np.random.seed(a.seed)
    torch.manual_seed(a.seed)
    rng = np.random.default_rng(a.seed)

    lab_dirs = sorted(
        os.path.join(a.data, d) for d in os.listdir(a.data) if d.startswith("lab-") and os.path.isdir(os.path.join(a.data, d))
    )
    other = os.path.join(a.data, "other-lab")
    lab = load(lab_dirs)
    train, test = split_by_ball(lab)
    other_lab = load([other]) if os.path.isdir(other) else None
    print(f"train {len(train['x'])} crops, test {len(test['x'])}, other-lab {0 if other_lab is None else len(other_lab['x'])}")
    print(f"logo-less share: train {1 - train['vis'].mean():.3f}")

    model = Head(ARCHS[a.arch]())
    params = sum(p.numel() for p in model.parameters())
    opt = torch.optim.AdamW(model.parameters(), lr=a.lr, weight_decay=1e-4)
    steps = a.epochs * math.ceil(len(train["x"]) / a.batch)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=a.lr, total_steps=steps)
    x_all = torch.from_numpy(train["x"]).permute(0, 3, 1, 2).contiguous()
    vis_all = torch.from_numpy(train["vis"])
    logo_all = torch.from_numpy(train["logo"])
    t_start = time.time()
    history = []
    for epoch in range(a.epochs):
        model.train()
        perm = torch.from_numpy(rng.permutation(len(x_all)))
        t0, total, n = time.time(), 0.0, 0
        for i in range(0, len(perm), a.batch):
            idx = perm[i : i + a.batch]
            x = x_all[idx].float() / 255.0
            x, logo = augment(x, logo_all[idx], rng, a.jitter)
            q = torch.from_numpy(swing_quaternion(logo.numpy()))
            out = model.raw(x)
            loss = conditional_loss(out, vis_all[idx], q, a.loss, a.orientation_weight)
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
            total += loss.item() * len(idx)
            n += len(idx)
        m = evaluate(model, test)
        history.append({"epoch": epoch + 1, "loss": total / n, "seconds": time.time() - t0, **m})
        print(
            f"epoch {epoch + 1:3d} loss {total / n:.4f} {time.time() - t0:5.1f}s  test: acc "
            f"{m['classification_accuracy']:.3f} geodesic {m['geodesic_deg_mean']:.2f} deg "
            f"vector {m['vector_angle_deg_mean']:.2f} deg",
            flush=True,
        )

    export(model, a.out)
    metrics = {
        "arch": a.arch,
        "parameters": int(params),
        "onnx_bytes": os.path.getsize(a.out),
        "loss": a.loss,
        "epochs": a.epochs,
        "seed": a.seed,
        "jitter": a.jitter,
        "train_crops": int(len(train["x"])),
        "train_seconds": time.time() - t_start,
        "torch_threads": torch.get_num_threads(),
        "test": evaluate(model, test),
        "other_lab": None if other_lab is None else evaluate(model, other_lab),
        "cpu": cpu_timing(model),
        "reference": reference_outputs(model, a.out),
        "history": history,
        "paper": {
            "classification_accuracy": 0.96,
            "geodesic_deg": 20.14,
            "vector_angle_deg": 4.23,
            "gpu_ms_per_image": 3.7,
            "gpu_ms_per_batch5": 5.5,
        },
    }
    with open(a.metrics, "w") as f:
        json.dump(metrics, f, indent=2)
    print(json.dumps({k: metrics[k] for k in ("test", "other_lab", "cpu", "parameters", "onnx_bytes")}, indent=2))


if __name__ == "__main__":
    main()

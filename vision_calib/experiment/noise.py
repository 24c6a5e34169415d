"""``vision-calib noise FOLDER``: camera noise from repeated frames of a static target, and the simulator
settings that reproduce it (vision-calib docs noise).

Input: a ROS-I noise-qualification set (``cal_data.yaml`` with ``data: [{image: ...}]``, ``intrinsics``,
``target_finder``; :func:`vision_calib.io.rosi.read_rosi_image_set`), or any folder of images with
``--target`` and ``--camera`` (which also override the ROS-I file's). Steps (:func:`measure_noise`):

1. every image read (unreadable, or another size than the first: DataError naming it) and detected with the
   detector ``process`` uses (``DetectConfig()``); a frame without the target is a DataError naming it;
2. fewer than 2 distinct frames (or frames that are pixel-identical copies): noise.json holds the detection
   and a DataError says the scatter needs >= 2 repeated frames;
3. corner scatter, per-frame pose scatter, "moved" frames (:mod:`vision_calib.measure.noise_qualification`;
   a moved frame is a DataError naming it, after noise.json is written);
4. pixel noise (photon-transfer fit), blur and grey levels fitted on the mean frame against the rendered pose
   (the dot diameter too when the target lacks it) (:mod:`.noise_sim`);
5. the simulator with those settings (``sim_frames`` frames): its corner scatter against the measured one;
   the grey noise scaled by their ratio ("settings that reproduce the corner noise": read noise x r, full
   well / r^2; standard error from the two scatters' chi-square dof), then simulated again with a new seed
   to report the corner and pose scatter the simulator then gives.

Outputs in ``out_dir``: noise.json (atomic), sensor.yaml (a scene snippet: camera, effects, measurement),
summary.txt.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import yaml

from ..camera import CameraIntrinsics
from ..errors import ConfigError, DataError
from ..serialize import jsonable, write_json_atomic, write_text_atomic
from ..io.portable import relative_ref
from ..measure.batch import detect_batch
from ..measure.detect import DetectConfig, load_gray
from ..measure.noise_qualification import (LEVEL, POSE_AXES, PixelAccumulator, Scatter, common_corners,
                                           corner_scatter, flat_mask, photon_transfer, pose_scatter,
                                           sensor_noise_settings)

if TYPE_CHECKING:  # the target kinds are imported where a target is loaded (read_noise_input)
    from ..targets import TargetSpec

FORMAT = "vision_calib.noise/1"
DEFAULT_SIM_FRAMES = 30
_CI = f"ci{int(LEVEL * 100)}"


@dataclass(frozen=True)
class NoiseInput:
    """images: frame files in order; camera; target (TargetSpec); source: what was read (for messages); skipped:
    the reasons of the frames left out (another size than the majority's: ``io.images.folder_sizes``)."""

    images: tuple
    camera: CameraIntrinsics
    target: TargetSpec
    source: str
    skipped: tuple = ()


def read_noise_input(folder: str | Path, target: str | Path | None = None, camera: str | Path | None = None,
                     allow_symlinks: bool = False) -> NoiseInput:
    """The frames, camera and target of a noise set (module docstring). target / camera: paths of a target YAML /
    camera.yaml (calibrate-camera's) overriding the ROS-I file's, required for a plain image folder."""
    from ..io.camera_file import load_camera_for_images
    from ..io.images import check_principal_point, folder_sizes
    from ..measure.intrinsics import find_images
    from ..targets import load_target
    from ..targets.spec import target_from_dict

    folder = Path(folder)
    rosi = folder.is_file() or (folder / "cal_data.yaml").is_file()
    if rosi:
        from ..io.rosi import read_rosi_image_set

        s = read_rosi_image_set(folder, allow_symlinks, with_target=target is None)
        images, source = s["images"], str(s["index"])
        spec = load_target(target) if target else target_from_dict(s["target"], f"{s['index']}: target_finder")
    else:
        if target is None or camera is None:
            raise ConfigError(f"{folder}: no cal_data.yaml (ROS-I noise-qualification layout): give the target and "
                              "the camera: --target TARGET.yaml --camera CAMERA.yaml")
        images = find_images(folder, allow_symlinks, hint="--allow-symlinks, or --allow-path DIR")
        source, spec = str(folder), load_target(target)
    size, sizes, odd = folder_sizes(images, "frames")  # headers only: a frame beyond the pixel limit is refused
    if size is None:
        raise DataError(f"{images[0]}: unreadable image (not an image file, or corrupt)")
    images = [p for p in images if sizes.get(p, size) == size]  # the odd-sized frames skipped (named)
    if camera is not None:
        cam = load_camera_for_images(camera, size, "--camera")
    else:
        k = s["intrinsics"]
        check_principal_point(k, size, s["intrinsics_where"])
        cam = CameraIntrinsics(size[0], size[1], k["fx"], k["fy"], k["cx"], k["cy"], tuple(s["dist"]))
    _check_memory(len(images), size)
    return NoiseInput(tuple(Path(p) for p in images), cam, spec, source, tuple(odd))


#: bytes per pixel the noise measurement holds at once besides the frames (uint8 each): the pixel accumulator's
#: float64 sum, sum of squares and mean, the mean frame and rendered images of the fit (counted from the code:
#: 3 + 2 float64 arrays = 40 B/px, rounded up)
NOISE_BYTES_PER_PIXEL = 48


def _check_memory(n_frames: int, size) -> None:
    """DataError when the frames (decoded at once) and the measurement's working arrays need more than half this
    machine's memory (``config.machine_memory_bytes``)."""
    from ..config import machine_memory_bytes

    need = size[0] * size[1] * (n_frames + NOISE_BYTES_PER_PIXEL)
    have = machine_memory_bytes()
    if have and need > have / 2:
        raise DataError(f"noise: {n_frames} frames of {size[0]}x{size[1]} px need about {need / 2**30:.3g} GiB of "
                        f"memory, more than half of this machine's {have / 2**30:.3g} GiB: give fewer or smaller "
                        "frames")


def _load_frames(inp: NoiseInput) -> list:
    """(H, W) uint8 frames; DataError naming an unreadable image or one of another size than the camera's
    (their headers were checked by :func:`read_noise_input`: nothing beyond the pixel limit is decoded)."""
    out = []
    for i, p in enumerate(inp.images):
        img, why = load_gray(p)
        if img is None:
            raise DataError(f"frame {i}: {why}")
        if (img.shape[1], img.shape[0]) != inp.camera.size:
            first = "the camera file" if i == 0 else f"the first image {inp.images[0]}"
            raise DataError(f"frame {i}: {p}: image size {img.shape[1]}x{img.shape[0]} differs from {first} "
                            f"({inp.camera.width}x{inp.camera.height}): every frame must come from the same camera "
                            "at the same resolution")
        out.append(img)
    return out


def _pose_table(ps, predicted=True) -> dict:
    out = {}
    for j, (name, unit, _) in enumerate(POSE_AXES):
        out[name] = ps.axes[name].to_dict(unit)
        if predicted:
            out[name][f"predicted_std_{unit}"] = float(ps.predicted_std[j])
    return out


def _ratio(a: Scatter, b: Scatter) -> dict:
    """a.std / b.std with the CI of the ratio of two independent chi-square stds (normal approx. in log)."""
    r = a.std / b.std
    se = float(np.sqrt(a.rel_se**2 + b.rel_se**2))
    return {"ratio": float(r), "rel_se": se, _CI: [float(r * np.exp(-1.96 * se)), float(r * np.exp(1.96 * se))]}


def _detection_summary(inp: NoiseInput, det, ids_all) -> dict:
    """What one frame's detection found: counts, PnP RMS and distance (the single-image report)."""
    from ..measure.pnp import solve_pnp_planar, target_lookup, undistort_px

    d = {"image": str(inp.images[det.frame_index]), "valid": bool(det.valid), "reason": det.reason,
         "n_corners": det.n_corners, "n_target_corners": len(ids_all)}
    if det.valid and det.n_corners >= 4:
        lookup = target_lookup(inp.target)
        p = np.array([lookup[int(i)] for i in det.ids])
        try:
            T, res = solve_pnp_planar(p, undistort_px(det.uv_px, inp.camera), inp.camera)
            d["pnp_rms_px"] = float(np.sqrt(np.mean(np.sum(res**2, axis=1))))
            d["distance_m"] = float(np.linalg.norm(T[:3, 3]))
        except Exception as exc:  # a detection report, not a failure
            d["pnp_error"] = str(exc).splitlines()[0]
    return d


def _one_frame_fit(inp: NoiseInput, det, img) -> dict | None:
    """Blur, levels (and a missing dot diameter) fitted on a single frame (the report of a set too small for the
    scatter); None when the fit is not possible on it."""
    from .noise_sim import fit_blur_levels, fit_dot_diameter, mean_pose_of, render_ideal

    try:
        spec, fd, mean = inp.target, None, img.astype(np.float64)
        if spec.kind == "modified_circle_grid" and not spec.diameter_m > 0:
            fd = fit_dot_diameter(spec, inp.camera, det.ids, det.uv_px, mean)
            spec = replace(spec, diameter_m=fd["diameter_m"], origin_diameter_m=0.0)
        ideal, _ = render_ideal(spec, inp.camera, mean_pose_of(spec, det.ids, det.uv_px, inp.camera))
        return {**fit_blur_levels(mean, ideal, det.uv_px), **({"dot_diameter": fd} if fd else {})}
    except (DataError, ConfigError, ValueError, np.linalg.LinAlgError):
        return None


def measure_noise(folder: str | Path, out_dir: str | Path, target: str | Path | None = None,
                  camera: str | Path | None = None, sim_frames: int = DEFAULT_SIM_FRAMES, seed: int = 0,
                  allow_symlinks: bool = False, detect_config: DetectConfig = DetectConfig()) -> dict:
    """Measure the noise of a folder of repeated frames of a static target and fit the simulator settings that
    reproduce it (module docstring). Writes noise.json, sensor.yaml, summary.txt in out_dir; returns the
    noise.json dict (+ "summary_text"). DataError (after writing noise.json where there is something to report)
    for fewer than 2 frames and for moved frames."""
    from ..sensor import SensorEffects
    from .noise_sim import fit_blur_levels, fit_dot_diameter, mean_pose_of, render_ideal, simulate_scatter

    inp = read_noise_input(folder, target, camera, allow_symlinks)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    imgs = _load_frames(inp)
    dets = detect_batch(imgs, inp.target, inp.camera, detect_config)
    ids_all = inp.target.corner_points()[0]
    doc = {"format": FORMAT, "source": relative_ref(inp.source, out_dir), "camera": inp.camera.to_dict(),
           "target": inp.target.to_dict(), "n_frames": len(imgs), "skipped_frames": list(inp.skipped),
           "frames": [{"image": relative_ref(p, out_dir), "valid": bool(d.valid), "reason": d.reason,
                       "n_corners": d.n_corners} for p, d in zip(inp.images, dets)]}
    bad = [d for d in dets if not d.valid]
    if bad:
        d = bad[0]
        raise DataError(f"frame {d.frame_index}: {inp.images[d.frame_index]}: target not detected ({d.reason}); "
                        "every frame must show the static target (remove this image or fix the target file)")
    distinct = len({p.resolve() for p in inp.images})
    acc = PixelAccumulator()
    for im in imgs:
        acc.add(im)
    copies = len(acc.identical_to_first) == len(imgs) - 1
    if len(imgs) < 2 or distinct < 2 or copies:
        det = _detection_summary(inp, dets[0], ids_all)
        doc["detection"] = det
        what = (f"{len(imgs)} frame" if len(imgs) < 2 else
                f"{len(imgs)} entries name {distinct} image file" if distinct < 2 else
                f"the {len(imgs)} frames are pixel-identical copies")
        one = _one_frame_fit(inp, dets[0], imgs[0]) if "pnp_rms_px" in det else None
        if one:
            doc["image_fit_one_frame"] = one
        found = (f"{det['n_corners']} of {det['n_target_corners']} target points detected"
                 + (f", PnP reprojection RMS {det['pnp_rms_px']:.3g} px, target at {det['distance_m']:.3f} m"
                    if "pnp_rms_px" in det else "")
                 + (f"; image fit of this frame: blur {one['blur_sigma_px']:.3g} +- {one['blur_se_px']:.2g} px"
                    + (f", dot diameter {one['dot_diameter']['diameter_m'] * 1e3:.4g} mm"
                       if "dot_diameter" in one else "")
                    if one else ""))
        msg = (f"{inp.source}: the scatter needs >= 2 repeated frames of the static target ({what}); detection on "
               f"{inp.images[0]}: {found} (written to {out_dir / 'noise.json'})")
        doc["error"] = msg
        write_json_atomic(out_dir / "noise.json", doc)
        raise DataError(msg)
    if acc.identical_to_first:
        raise DataError(f"frames {acc.identical_to_first} are pixel-identical copies of frame 0 "
                        f"({inp.images[0]}): copies carry no noise; give only distinct frames")

    # --- measured from the frames alone
    ids, uv = common_corners(dets)
    if len(ids) < 4:
        raise DataError(f"only {len(ids)} target points are detected in every frame (>= 4 needed for the pose)")
    cs = corner_scatter(uv)
    ps = pose_scatter(ids, uv, inp.target, inp.camera, cs["xy"].std)
    doc["corner_noise"] = _corner_doc(cs, ids)
    doc["moved"] = {"threshold_mahalanobis2": ps.moved_threshold, "p": 1e-6,
                    "mahalanobis2": ps.mahalanobis2.tolist(),
                    "frames": [{"frame": f, "image": doc["frames"][f]["image"], "mahalanobis2": m, "shift_px": s}
                               for f, m, s in ps.moved]}
    if ps.moved:
        names = "; ".join(f"frame {f} ({inp.images[f].name}): mean corner shift {s:.3g} px" for f, _, s in ps.moved)
        msg = (f"the target or the camera moved between frames: {names} from the median pose, far above the "
               f"corner noise ({ps.residual_noise_px.std:.3g} px after each frame's own pose): the scatter would "
               "not be noise; remove these frames or re-shoot with everything fixed")
        doc["error"] = msg
        write_json_atomic(out_dir / "noise.json", doc)
        raise DataError(msg)
    mean, var = acc.mean, acc.var
    pt = photon_transfer(mean, var, flat_mask(mean, var, acc.n), acc.n)

    # --- simulator fit: dot diameter (if unknown), blur and levels, then the noise
    spec, fit_d = inp.target, None
    if spec.kind == "modified_circle_grid" and not spec.diameter_m > 0:
        fit_d = fit_dot_diameter(spec, inp.camera, ids, uv.mean(axis=0), mean)
        spec = replace(spec, diameter_m=fit_d["diameter_m"], origin_diameter_m=0.0)
        ps = pose_scatter(ids, uv, spec, inp.camera, cs["xy"].std)  # the fitted board's origin
    doc["pose_scatter"] = {"convention": "per frame: pose_error(T_mean, T_f): translation of the target frame's "
                                         "origin [mm] and rotation vector of R_f R_mean^T [mrad], both in camera "
                                         "axes; predicted: from the corner noise, sigma^2 (J^T J)^-1",
                           "axes": _pose_table(ps), "T_cam_target_mean": ps.T_mean.tolist(),
                           "per_frame": ps.deltas.tolist()}
    T = mean_pose_of(spec, ids, uv.mean(axis=0), inp.camera)
    ideal, _ = render_ideal(spec, inp.camera, T)
    fb = fit_blur_levels(mean, ideal, uv.mean(axis=0))
    ns = sensor_noise_settings(pt, fb["black_level_grey"], fb["black_se"])
    doc["pixel_noise"] = {"model": "var = c0 + c1 mean over flat pixels; read^2 = c0 + c1 black - 1/12, "
                                   "full_well_e = 255 / c1 (gain 1)", **{k: pt[k] for k in ("c0", "c1", "reduced_chi2",
                                                                                         "photon", "bins")},
                          "cov": np.asarray(pt["cov"]).tolist(), **ns}
    doc["image_fit"] = {**fb, **({"dot_diameter": fit_d} if fit_d else {})}
    if not (ns["read_noise_grey"] > 0 or ns["full_well_e"] > 0):
        raise DataError(f"{inp.source}: the frames show no pixel noise on flat areas (identical but for a few "
                        "pixels?): give raw repeated frames of the camera")
    base = dict(blur_sigma_px=fb["blur_sigma_px"], exposure=fb["exposure"], black_level_grey=fb["black_level_grey"],
                gain=1.0, apply_distortion=True)
    eff0 = SensorEffects(read_noise_grey=ns["read_noise_grey"], full_well_e=ns["full_well_e"], **base)
    s0 = simulate_scatter(spec, inp.camera, T, eff0, sim_frames, seed, detect_config)
    r = _ratio(cs["xy"], s0["corners"]["xy"])
    k = r["ratio"]
    eff = replace(eff0, read_noise_grey=ns["read_noise_grey"] * k,
                  full_well_e=ns["full_well_e"] / k**2 if ns["full_well_e"] > 0 else 0.0)
    s1 = simulate_scatter(spec, inp.camera, T, eff, sim_frames, seed + 1, detect_config)
    settings = {"blur_sigma_px": [fb["blur_sigma_px"], fb["blur_se_px"]],
                "read_noise_grey": [eff.read_noise_grey, eff.read_noise_grey * r["rel_se"]],
                "full_well_e": [eff.full_well_e, 2 * eff.full_well_e * r["rel_se"]],
                "exposure": [fb["exposure"], fb["exposure_se"]],
                "black_level_grey": [fb["black_level_grey"], fb["black_se"]]}
    doc["simulator"] = {
        "frames": int(sim_frames), "seed": int(seed), "target": spec.to_dict(),
        "with_pixel_noise": {"effects": eff0.to_dict(), "corner_noise": _corner_doc(s0["corners"]),
                             "measured_over_simulated": r},
        "settings": {"value_and_se": settings, "effects": eff.to_dict(),
                     "note": "grey noise = the pixel noise scaled by measured/simulated corner noise (x "
                             f"{k:.4g}); standard errors: blur and levels from the patch scatter, noise from the "
                             "two corner scatters' chi-square dof"},
        "reproduced": {"seed": int(seed) + 1, "corner_noise": _corner_doc(s1["corners"]),
                       "measured_over_simulated": _ratio(cs["xy"], s1["corners"]["xy"]),
                       "pose_scatter": _pose_table(s1["pose"], predicted=False)}}
    snippet = _sensor_yaml(inp, eff, settings, ps, k)
    write_text_atomic(out_dir / "sensor.yaml", snippet)
    doc["outputs"] = {"json": "noise.json", "sensor_yaml": "sensor.yaml", "summary": "summary.txt"}
    text = summary_text(doc, inp)
    write_text_atomic(out_dir / "summary.txt", text + "\n")
    write_json_atomic(out_dir / "noise.json", jsonable(doc))
    return {**doc, "summary_text": text + f"\nwrote {out_dir / 'noise.json'}, {out_dir / 'sensor.yaml'}"}


def _corner_doc(cs: dict, ids=None) -> dict:
    d = {ax: cs[ax].to_dict("px") for ax in ("x", "y", "xy")}
    per = cs["per_corner_std_px"]
    d["per_corner_std_px"] = {"median": float(np.median(np.hypot(*per.T) / np.sqrt(2))),
                              "max": float(np.max(np.hypot(*per.T) / np.sqrt(2)))}
    d["n_corners"] = int(per.shape[0])
    if ids is not None:
        d["convention"] = ("each corner's detected position (distorted px) minus its mean over the frames; std per "
                           f"coordinate pooled over the corners seen in every frame; {_CI}: chi-square interval")
    return d


def _sensor_yaml(inp: NoiseInput, eff, settings: dict, ps, k: float) -> str:
    """A scene snippet: the camera, the fitted effects (with their standard errors as comments) and the per-frame
    pose noise for the synthetic mode."""
    t = np.array([ps.axes[a].std for a in ("tx", "ty", "tz")])
    rr = np.array([ps.axes[a].std for a in ("rx", "ry", "rz")])
    head = (f"# Simulator settings that reproduce {inp.source} ({len(inp.images)} frames; vision-calib noise).\n"
            "# Paste the blocks into a scene (scenes/*.yaml); studies (scenes/studies/) then start from this camera.\n"
            f"# Grey noise: pixel noise scaled x {k:.4g} so that the simulated corner scatter matches the measured "
            "one.\n")
    cam = {"camera": inp.camera.to_dict()}
    lines = ["effects:"]
    for key in ("read_noise_grey", "full_well_e", "blur_sigma_px", "exposure", "black_level_grey"):
        v, se = settings[key]
        lines.append(f"  {key}: {float(f'{v:.5g}')}   # +- {se:.2g}")
    lines.append("  gain: 1.0")
    meas = ("# synthetic (no-image) mode: pose noise of ONE frame at this target pose, RMS over the axes (camera "
            f"frame; per axis tx ty tz = {', '.join(f'{x:.3g}' for x in t)} mm, rx ry rz = "
            f"{', '.join(f'{x:.3g}' for x in rr)} mrad); divide by sqrt(frames) for averaged frames\n"
            f"measurement: {{sigma_mm: {float(f'{np.sqrt(np.mean(t**2)):.4g}')}, "
            f"sigma_deg: {float(f'{np.degrees(np.sqrt(np.mean(rr**2)) * 1e-3):.4g}')}}}\n")
    return head + yaml.safe_dump(cam, sort_keys=False, default_flow_style=None) + "\n".join(lines) + "\n" + meas


def _fmt_scatter(d: dict) -> str:
    lo, hi = d[f"{_CI}_px"]
    return f"{d['std_px']:.4g} [{lo:.4g}, {hi:.4g}]"


def summary_text(doc: dict, inp: NoiseInput) -> str:
    """The printed summary of a noise.json dict."""
    c, pn, fb, sim = doc["corner_noise"], doc["pixel_noise"], doc["image_fit"], doc["simulator"]
    lines = [f"warning: frame skipped: {w}" for w in doc.get("skipped_frames") or ()]
    lines += [f"noise: {doc['n_frames']} frames of {inp.source} ({inp.camera.width}x{inp.camera.height}, target "
             f"{inp.target.kind} {inp.target.cols}x{inp.target.rows}, {c['n_corners']} points in every frame)",
             f"corner noise about each point's mean [px, {_CI[2:]} % CI]: x {_fmt_scatter(c['x'])}, y "
             f"{_fmt_scatter(c['y'])} (dof {c['x']['dof']} each); per point median "
             f"{c['per_corner_std_px']['median']:.3g}, max {c['per_corner_std_px']['max']:.3g}",
             "pose scatter of one frame (target origin, camera axes) std [CI] (predicted from the corner noise):"]
    for name, unit, _ in POSE_AXES:
        a = doc["pose_scatter"]["axes"][name]
        lo, hi = a[f"{_CI}_{unit}"]
        lines.append(f"  {name} {a[f'std_{unit}']:.4g} {unit} [{lo:.3g}, {hi:.3g}] ({a[f'predicted_std_{unit}']:.3g})")
    lines.append(f"pixel noise (flat pixels): read {pn['read_noise_grey']:.3g} +- {pn['read_noise_se']:.2g} grey, "
                 + (f"full well {pn['full_well_e']:.4g} +- {pn['full_well_se']:.2g} e- (photon noise)"
                    if pn["photon"] else "no photon noise measurable")
                 + f" (fit reduced chi2 {pn['reduced_chi2']:.3g})")
    if "dot_diameter" in fb:
        dd = fb["dot_diameter"]
        lines.append(f"dot diameter (not in the target file, fitted): {dd['diameter_m'] * 1e3:.3g} +- "
                     f"{dd['diameter_se_m'] * 1e3:.2g} mm")
    lines.append(f"image fit ({fb['patches']} patches of the mean frame vs the rendered pose): blur "
                 f"{fb['blur_sigma_px']:.3g} +- {fb['blur_se_px']:.2g} px, black level {fb['black_level_grey']:.4g} +- "
                 f"{fb['black_se']:.2g} grey, exposure {fb['exposure']:.4g} +- {fb['exposure_se']:.2g} (spread over "
                 f"the board {100 * fb['exposure_spread']:.2g} %)"
                 + (" [blur at the grid's 4 px limit]" if fb["at_grid_edge"] else ""))
    w = sim["with_pixel_noise"]
    r = w["measured_over_simulated"]
    lines.append(f"simulator ({sim['frames']} frames) with the pixel noise: corner noise "
                 f"{_fmt_scatter(w['corner_noise']['xy'])} px; measured / simulated {r['ratio']:.3g} "
                 f"[{r[_CI][0]:.3g}, {r[_CI][1]:.3g}]")
    s = sim["settings"]["value_and_se"]
    lines.append("settings that reproduce it: " + ", ".join(
        f"{k} {v:.4g} +- {se:.2g}" for k, (v, se) in s.items()))
    rep = sim["reproduced"]
    lines.append(f"simulator with them (seed {rep['seed']}): corner noise {_fmt_scatter(rep['corner_noise']['xy'])} px "
                 f"(measured {_fmt_scatter(c['xy'])}); pose scatter " + ", ".join(
                     f"{n} {rep['pose_scatter'][n][f'std_{u}']:.3g} {u}" for n, u, _ in POSE_AXES))
    return "\n".join(lines)


__all__ = ["measure_noise", "read_noise_input", "summary_text", "NoiseInput", "DEFAULT_SIM_FRAMES"]

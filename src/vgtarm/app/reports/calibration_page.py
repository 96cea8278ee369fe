"""The pages of ``vgtarm calibrate`` (``calibration.html``) and ``vgtarm identify``
(``identification.html``): each command's summary as Markdown (the fit, what the data determine and
what they do not, the parameters with their standard errors, the checks) and its PNG figures
inlined: one self-contained file each, as the workspace page (:mod:`.workspace_page`: the same
style, the Markdown converted by :mod:`.markdown_html`).

The summaries are plain data (SI units) built by the commands. Every string in them that a user
wrote (the robot's name, the file names, joint and body names, and so the parameters' names and
the base combinations, which carry them) goes through :func:`vgtarm.markup.md_text` or
:func:`~vgtarm.markup.md_cell` into the Markdown and :func:`~vgtarm.markup.html_text` into the
title, so it shows as written and adds no element, link or table column. A parameter the data do
not determine is said to be so: no value and no standard error is shown for it.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from ...markup import html_text, md_cell, md_code, md_text, url_path
from .html import _STYLE, FIGURES_HEADING, _embedded_image
from .markdown_html import to_html

__all__ = ["calibration_html", "calibration_markdown", "identification_html", "identification_markdown"]

#: What a table shows for a number the data do not determine (never a made-up value).
UNDETERMINED = "not determined"


def _mm(value: float | None, digits: int = 4) -> str:
    """A length (m) in mm, or :data:`UNDETERMINED`."""
    return UNDETERMINED if value is None else f"{1e3 * value:.{digits}f}"


def _g(value: float | None, digits: int = 6) -> str:
    """A number in ``digits`` significant figures; ``None`` (and NaN) as :data:`UNDETERMINED`."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return UNDETERMINED
    return f"{value:.{digits}g}"


def _figures(pictures: Sequence[str | Path]) -> list[str]:
    """The "Figures" section: each picture (a PNG file) under its file name."""
    lines = ["", f"## {FIGURES_HEADING}", ""]
    for picture in pictures:
        name = Path(picture).name
        lines.append(f"![{md_text(name)}]({url_path(name)})\n")
    return lines


def _images(pictures: Sequence[str | Path]) -> Callable[[str, str], str]:
    """The image callback of :func:`.markdown_html.to_html`: each picture's PNG inlined from its own
    folder (:func:`.html._embedded_image`); an unknown name shows its caption."""
    by_name = {url_path(Path(p).name): _embedded_image(Path(p).parent) for p in pictures}
    missing = _embedded_image(None)
    return lambda alt, name: by_name.get(name, missing)(alt, name)


def _page(title: str, markdown: str, pictures: Sequence[str | Path]) -> str:
    """The HTML document of ``markdown`` (its pictures inlined) under ``title`` (plain text)."""
    body = to_html(markdown, image=_images(pictures))
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        f"<title>{html_text(title)}</title>",
        f"<style>{_STYLE}</style></head><body>",
        body,
        "</body></html>",
    ]
    return "\n".join(parts) + "\n"


# -- calibration -----------------------------------------------------------------------------------


def _calibration_fit(summary: Mapping[str, Any]) -> list[str]:
    fit = summary["fit"]
    sigma = fit["sigma"]
    return [
        "## The fit",
        "",
        f"{summary['poses']} poses of {summary['joints']} joints from {md_code(summary['measurements'])}"
        + (" (positions and orientations)." if summary["orientation"] else " (positions)."),
        "",
        "| quantity | value |",
        "| --- | --- |",
        f"| RMS position residual, calibrated (mm per coordinate) | {_mm(fit['rms_residual_m'])} |",
        f"| RMS position residual, nominal model (mm per coordinate) | {_mm(fit['nominal_rms_residual_m'])} |",
        f"| assumed measurement noise (mm) | {_mm(summary['noise_m'])} |",
        f"| noise estimated from the residuals (times the assumed) | {sigma:.3g} |",
        f"| iterations (model evaluations) | {fit['iterations']} ({fit['evaluations']}) |",
        f"| converged | {'yes' if fit['success'] else 'no'}: {md_cell(fit['message'])} |",
        "",
    ]


def _calibration_identifiability(summary: Mapping[str, Any]) -> list[str]:
    found = summary["identifiability"]
    sigma = summary["fit"]["sigma"]
    lines = [
        "## Identifiability",
        "",
        f"Rank {found['rank']} of {found['parameters']} parameters: singular values of the identification "
        f"Jacobian (weighted by the noise, 1/m) above {found['tolerance']:.4g} determine their direction. "
        "The standard error along a direction is the estimated noise over its singular value.",
        "",
        "| direction | singular value (1/m) | standard error along it (mm) | determined |",
        "| --- | --- | --- | --- |",
    ]
    for k, value in enumerate(found["singular_values"], start=1):
        determined = value > found["tolerance"]
        error = _mm(sigma / value, 4) if determined else UNDETERMINED
        lines.append(f"| {k} | {value:.4g} | {error} | {'yes' if determined else 'no'} |")
    lines.append("")
    if found["undetermined"]:
        lines += ["Not determined by these poses (one parameter of each is held at its nominal value):", ""]
        lines += [f"- {md_text(text)}" for text in found["undetermined"]]
    else:
        lines.append("Every parameter is determined by these poses.")
    return [*lines, ""]


def _calibration_parameters(summary: Mapping[str, Any]) -> list[str]:
    lines = [
        "## The parameters",
        "",
        "Lengths and leg-sensor offsets (mm). *held*: not determined by the poses, kept at its nominal "
        "value; *given held*: determined once the held parameters are fixed.",
        "",
        "| parameter | nominal (mm) | identified (mm) | change (mm) | standard error (mm) | status |",
        "| --- | --- | --- | --- | --- | --- |",
    ]
    for row in summary["parameters"]:
        value, error = row["identified"], row["standard_error"]
        change = "" if value is None else f"{1e3 * (value - row['nominal']):+.4f}"
        status = "held at nominal" if value is None else md_cell(row["status"])
        lines.append(
            f"| {md_cell(row['name'])} | {_mm(row['nominal'])} | {_mm(value)} | {change} | {_mm(error)} | {status} |"
        )
    offsets = summary["offsets"]
    text = ", ".join(f"{md_text(k)} {1e3 * v:+.4f} mm" for k, v in offsets.items()) or "none fitted"
    lines += ["", f"Sensor offsets (subtract them from the readings; not part of a robot file): {text}.", ""]
    return lines


def _calibration_conditioning(summary: Mapping[str, Any]) -> list[str]:
    found = summary["conditioning"]
    lines = [
        "## The choice of poses",
        "",
        f"Condition number of the identification Jacobian of the free parameters (positions only): "
        f"{found['condition_number']:.4g} for these {summary['poses']} poses.",
    ]
    random = found.get("random")
    if random:
        lines.append(
            f"{random['trials']} random sets of as many poses (from {random['candidates']} candidates within the "
            f"limits, seed {random['seed']}): median {random['median']:.4g}, best {random['best']:.4g}, "
            f"worst {random['worst']:.4g}. `vgtarm calibrate --plan-poses` chooses poses that lower it."
        )
    else:
        lines.append("No random poses to compare with (too few candidates assemble).")
    return [*lines, ""]


def calibration_markdown(summary: Mapping[str, Any], pictures: Sequence[str | Path]) -> str:
    """The calibration page's Markdown from ``summary`` (built by ``vgtarm calibrate``: the fit, the
    identifiability, the parameters, the pose conditioning, the written robot file) and ``pictures``
    (PNG files) under "Figures"."""
    lines = [
        f"# Kinematic calibration of {md_text(summary['robot'])}",
        "",
        f"Corrected robot file: {md_code(summary['robot_file'])} (the undetermined parameters at their "
        "nominal values; the sensor offsets are in its header).",
        "",
        *_calibration_fit(summary),
        *_calibration_identifiability(summary),
        *_calibration_parameters(summary),
        *_calibration_conditioning(summary),
        *_figures(pictures),
    ]
    return "\n".join(lines) + "\n"


def calibration_html(summary: Mapping[str, Any], pictures: Sequence[str | Path]) -> str:
    """``calibration.html``: :func:`calibration_markdown` as a self-contained page, ``pictures`` (paths
    of PNG files) inlined."""
    return _page(f"vgtarm: calibration of {summary['robot']}", calibration_markdown(summary, pictures), pictures)


# -- identification --------------------------------------------------------------------------------


def _identification_trajectory(summary: Mapping[str, Any]) -> list[str]:
    found = summary["trajectory"]
    lines = [
        "## The trajectory",
        "",
        f"{summary['samples']} samples of {summary['joints']} joints from {md_code(summary['data'])}; "
        f"condition number of the column-normalised base regressor along it: {found['condition_number']:.4g} "
        "(lower excites the base parameters more evenly). Ranges as a percentage of each joint's span.",
        "",
        "| joint | unit | lower limit | upper limit | min | max | span used | max abs rate | max abs accel. "
        "| RMS force (N, N m) |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for row in found["joints"]:
        lines.append(
            f"| {md_cell(row['name'])} | {md_cell(row['unit'])} | {row['lower']:.4g} | {row['upper']:.4g} | "
            f"{row['min']:.4g} | {row['max']:.4g} | {100 * row['span_used']:.1f} % | {row['max_rate']:.4g} | "
            f"{row['max_acceleration']:.4g} | {row['rms_force']:.4g} |"
        )
    return [*lines, ""]


def _identification_base(summary: Mapping[str, Any]) -> list[str]:
    found = summary["base"]
    lines = [
        "## The base parameters",
        "",
        f"{len(found['parameters'])} identifiable combinations of the {found['standard']} standard parameters "
        "(ten per body about its frame's origin, then one viscous coefficient per joint): the weighted "
        "least-squares estimate with its standard error, the physically consistent estimate, the prior's value. "
        "Units: those of the leading parameter.",
        "",
        "| base parameter | unit | least squares | standard error | relative | consistent | prior |",
        "| --- | --- | --- | --- | --- | --- | --- |",
    ]
    for row in found["parameters"]:
        value, error = row["least_squares"], row["standard_error"]
        percent = 100 * error / abs(value) if value else None
        relative = "" if percent is None else f"{percent:.2g} %" if percent < 100 else f"{percent:.0f} %"
        lines.append(
            f"| {md_cell(row['label'])} | {md_cell(row['unit'])} | {_g(value)} | {_g(error, 3)} | {relative} | "
            f"{_g(row['consistent'])} | {_g(row['prior'])} |"
        )
    lines.append("")
    if found["undetermined"]:
        names = ", ".join(md_text(name) for name in found["undetermined"])
        lines.append(f"Not determined (no force depends on them; kept at the prior's values, not estimated): {names}.")
    else:
        lines.append("Every standard parameter enters a base parameter.")
    return [*lines, ""]


def _identification_consistency(summary: Mapping[str, Any]) -> list[str]:
    found = summary["consistency"]
    lines = [
        "## Physical consistency",
        "",
        "Each body of the identified robot: its mass, the principal moments of its inertia about the centre "
        "of mass, the least triangle margin `I_j + I_k - I_i` of them, and whether its pseudo-inertia is "
        "positive definite (all three hold then).",
        "",
        "| body | mass (kg) | centre of mass (mm) | principal moments (kg m^2) | triangle margin (kg m^2) "
        "| consistent |",
        "| --- | --- | --- | --- | --- | --- |",
    ]
    for body in found["bodies"]:
        com = ", ".join(f"{1e3 * c:.2f}" for c in body["com_m"])
        moments = ", ".join(f"{m:.4g}" for m in body["principal_moments"])
        lines.append(
            f"| {md_cell(body['name'])} | {body['mass']:.4g} | {com} | {moments} | "
            f"{body['triangle_margin']:.3g} | {'yes' if body['consistent'] else '**no**'} |"
        )
    viscous = ", ".join(f"{md_text(k)} {v:.4g}" for k, v in found["viscous"].items())
    lines += [
        "",
        f"Viscous coefficients (N s/m, N m s/rad for a twist; bounded below by 0): {viscous}.",
        "",
        f"Consistent fit: {'converged' if found['success'] else 'stopped before its tolerances'} "
        f"({md_text(found['message'])}).",
        "",
    ]
    return lines


def _identification_validation(summary: Mapping[str, Any]) -> list[str]:
    found = summary["validation"]
    lines = [
        "## Validation",
        "",
        "| model | RMS force residual (N, N m) |",
        "| --- | --- |",
        f"| prior (the input robot) | {found['rms_prior']:.4g} |",
        f"| least squares (base parameters) | {found['rms_least_squares']:.4g} |",
        f"| physically consistent | {found['rms_consistent']:.4g} |",
        f"| the written robot file, read back | {found['rms_file']:.4g} |",
        "",
    ]
    holdout = found.get("holdout")
    if holdout is None:
        lines.append("Hold-out check not run: the first part of the data does not excite every base parameter.")
    else:
        lines.append(
            f"Hold-out check: fitted (least squares) on the first {holdout['fit_samples']} samples, the last "
            f"{holdout['test_samples']} are predicted with RMS residual {holdout['rms_prediction']:.4g} "
            f"(fit: {holdout['rms_fit']:.4g})."
        )
    lines += [
        "",
        "| joint | noise estimate | RMS residual (consistent) | RMS force | residual / force |",
        "| --- | --- | --- | --- | --- |",
    ]
    for row in found["joints"]:
        ratio = f"{100 * row['rms_residual'] / row['rms_force']:.2f} %" if row["rms_force"] else ""
        lines.append(
            f"| {md_cell(row['name'])} | {row['noise']:.4g} | {row['rms_residual']:.4g} | {row['rms_force']:.4g} "
            f"| {ratio} |"
        )
    return [*lines, ""]


def identification_markdown(summary: Mapping[str, Any], pictures: Sequence[str | Path]) -> str:
    """The identification page's Markdown from ``summary`` (built by ``vgtarm identify``: the
    trajectory, the base parameters, the consistency checks, the validation) and ``pictures`` (PNG
    files) under "Figures"."""
    lines = [
        f"# Dynamic identification of {md_text(summary['robot'])}",
        "",
        f"Identified robot file: {md_code(summary['robot_file'])} (the prior's geometry, the identified bodies "
        "and viscous friction).",
        "",
        *_identification_trajectory(summary),
        *_identification_base(summary),
        *_identification_consistency(summary),
        *_identification_validation(summary),
        *_figures(pictures),
    ]
    return "\n".join(lines) + "\n"


def identification_html(summary: Mapping[str, Any], pictures: Sequence[str | Path]) -> str:
    """``identification.html``: :func:`identification_markdown` as a self-contained page, ``pictures``
    (paths of PNG files) inlined."""
    title = f"vgtarm: identification of {summary['robot']}"
    return _page(title, identification_markdown(summary, pictures), pictures)

"""Encoding a run's frames (RGB arrays) into a video: H.264 in MP4, or a GIF with one palette.

Both go through PyAV (FFmpeg) and take the frames as an iterator, so a long run is encoded
streamed and memory does not grow with the number of frames.
"""
from __future__ import annotations

from fractions import Fraction
from pathlib import Path

import numpy as np


def write_mp4(out: Path, frames, fps: float) -> None:
    """H.264 in MP4 through PyAV (the library under imageio's video plugin, used directly for
    the encoder options): x264 preset "veryfast" encodes a frame faster than the default
    "medium" at the same quality (crf 23), with a file no larger (docs/speed.md)."""
    import av
    with av.open(str(out), mode="w", format="mp4") as container:
        stream = None
        for frame in frames:
            if stream is None:
                stream = container.add_stream("libx264", rate=Fraction(fps).limit_denominator(1000))
                stream.width, stream.height = frame.shape[1], frame.shape[0]
                stream.pix_fmt = "yuv420p"
                stream.codec_context.options = {"preset": "veryfast", "crf": "23"}
            container.mux(stream.encode(av.VideoFrame.from_ndarray(frame, format="rgb24")))
        if stream is not None:
            container.mux(stream.encode(None))


def write_gif(out: Path, frames, fps: float, palette_from: list[np.ndarray]) -> None:
    import av
    palette, lut = palette_for(np.concatenate(palette_from, axis=0))
    argb = np.zeros((256, 4), dtype=np.uint8)                    # PyAV's pal8 palette: ARGB
    argb[:len(palette), 0] = 255
    argb[:len(palette), 1:] = palette
    rate = Fraction(fps).limit_denominator(1000)
    with av.open(str(out), mode="w", format="gif") as container:
        stream = None
        for frame in frames:
            if stream is None:
                stream = container.add_stream("gif", rate=rate)
                stream.width, stream.height = frame.shape[1], frame.shape[0]
                stream.pix_fmt = "pal8"
            index = lut[frame[..., 0] >> 3, frame[..., 1] >> 3, frame[..., 2] >> 3]
            vf = av.VideoFrame.from_ndarray((index, argb), format="pal8")
            container.mux(stream.encode(vf))
        if stream is not None:
            container.mux(stream.encode(None))


def palette_for(sample: np.ndarray, colors: int = 256) -> tuple[np.ndarray, np.ndarray]:
    """A palette for ``sample`` [h, w, 3] by median cut (Pillow) → (palette [m, 3] uint8,
    lookup [32, 32, 32] uint8: index of the nearest palette colour for 5-bit RGB)."""
    from PIL import Image
    quantised = Image.fromarray(sample).quantize(colors=colors, method=Image.Quantize.MEDIANCUT,
                                                 dither=Image.Dither.NONE)
    flat = (quantised.getpalette() or [])[:3 * colors]
    flat += [0] * (3 * colors - len(flat))             # unused entries: black, never the nearest twice
    palette = np.array(flat, dtype=np.uint8).reshape(-1, 3)
    grid = (np.arange(32, dtype=np.float32) * 8 + 4)
    cube = np.stack(np.meshgrid(grid, grid, grid, indexing="ij"), axis=-1).reshape(-1, 3)
    best = np.empty(len(cube), dtype=np.uint8)
    pal = palette.astype(np.float32)
    for start in range(0, len(cube), 4096):          # chunks keep the distance matrix small
        block = cube[start:start + 4096]
        d = ((block[:, None, :] - pal[None, :, :]) ** 2).sum(axis=2)
        best[start:start + 4096] = np.argmin(d, axis=1)
    return palette, best.reshape(32, 32, 32)

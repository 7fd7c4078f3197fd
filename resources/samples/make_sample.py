"""Makes resources/samples/sample.tif, the demo image: an sRGB test chart (hue wheel,
grey and CMYK-primary ramps, a skin-tone patch row, fine lines and text), 1200 x 520 px,
LZW, 300 ppi.  Run: python resources/samples/make_sample.py"""

from pathlib import Path

import cv2
import numpy as np
import tifffile

W, H = 1200, 520


def chart() -> np.ndarray:
    img = np.full((H, W, 3), 255, np.uint8)
    yy, xx = np.mgrid[0:H, 0:W]
    # hue wheel
    cx, cy, rad = 200, 200, 170
    dx, dy = xx - cx, yy - cy
    r = np.hypot(dx, dy)
    hue = ((np.degrees(np.arctan2(dy, dx)) + 360) % 360 / 2).astype(np.uint8)
    sat = np.clip(r / rad * 255, 0, 255).astype(np.uint8)
    hsv = np.dstack([hue, sat, np.full_like(hue, 255)])
    wheel = cv2.cvtColor(hsv, cv2.COLOR_HSV2RGB)
    img[r <= rad] = wheel[r <= rad]
    # ramps: grey, red, green, blue, cyan, magenta, yellow
    x0, x1 = 420, 1180
    ramp = np.linspace(0, 1, x1 - x0)[None, :, None]
    colours = [(0, 0, 0), (255, 0, 0), (0, 160, 0), (0, 0, 255), (0, 174, 239),
               (236, 0, 140), (255, 242, 0)]
    for i, col in enumerate(colours):
        y = 20 + i * 42
        band = 255 - ramp * (255 - np.array(col, float)[None, None, :])
        img[y:y + 34, x0:x1] = np.repeat(band, 34, axis=0).astype(np.uint8)
    # skin tones and neutrals
    patches = [(255, 224, 196), (234, 192, 134), (198, 134, 66), (141, 85, 36), (128, 128, 128),
               (64, 64, 64)]
    for i, col in enumerate(patches):
        img[330:390, 420 + i * 110:420 + i * 110 + 100] = col
    # fine lines: 1, 2, 3 px
    for i, w in enumerate((1, 2, 3)):
        for k in range(8):
            x = 60 + i * 110 + k * 12
            img[400:500, x:x + w] = 0
    cv2.putText(img, "wideprint", (420, 470), cv2.FONT_HERSHEY_DUPLEX, 2.2, (20, 20, 20), 3,
                cv2.LINE_AA)
    cv2.putText(img, "XJ128 x 8  CMYK  3.4 m", (820, 500), cv2.FONT_HERSHEY_SIMPLEX, 0.8,
                (200, 0, 0), 2, cv2.LINE_AA)
    return img


if __name__ == "__main__":
    out = Path(__file__).with_name("sample.tif")
    tifffile.imwrite(out, chart(), photometric="rgb", compression="lzw",
                     resolution=(300, 300), resolutionunit="INCH")
    print(out, out.stat().st_size, "bytes")

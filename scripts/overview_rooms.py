"""Room labels on a house's top-down overview (``ctxsearch room`` with a house style)."""

from __future__ import annotations

import numpy as np

FONT = 0  # cv2.FONT_HERSHEY_SIMPLEX


def draw_room_labels(img: np.ndarray, world, layout) -> np.ndarray:
    """``img`` (BGR overview of ``world``) with every room's name and area written at the top
    of its outline and the entrance marked; a single room is returned unchanged."""
    import cv2

    if not layout.is_house:
        return img
    h, w = img.shape[:2]
    scale = 0.5 * max(1.0, h / 600)
    for room in layout.rooms:
        x0, y0, x1, y1 = room.outline
        (u0, v0), (u1, v1) = world.overview_pixels(np.array([[x0, y1], [x1, y0]]), w, h)
        label = f"{room.index}: {room.style.replace('_', ' ')} {room.area:.0f} m2"
        (tw, th), base = cv2.getTextSize(label, FONT, scale, 1)
        if tw > (u1 - u0) - 6:  # too long for a narrow room: the name alone
            label = f"{room.index}: {room.style.replace('_', ' ')}"
            (tw, th), base = cv2.getTextSize(label, FONT, scale, 1)
        u = int((u0 + u1) / 2 - tw / 2)
        v = int(v0 + th + 6)
        if room.style == "corridor":
            v = int((v0 + v1) / 2 + th / 2)
        cv2.rectangle(img, (u - 3, v - th - 3), (u + tw + 3, v + base), (40, 40, 40), -1)
        cv2.putText(img, label, (u, v), FONT, scale, (80, 230, 255), 1, cv2.LINE_AA)
    entrance = next(p for p in layout.doors if p.rooms[1] == -1)
    u, v = (int(x) for x in world.overview_pixels(np.array([entrance.center]), w, h)[0])
    cv2.circle(img, (u, v), 7, (40, 200, 40), -1, cv2.LINE_AA)
    (tw, th), _ = cv2.getTextSize("entrance", FONT, scale, 1)
    tu = u + 9 if u + 9 + tw < w else u - 9 - tw  # keep the word inside the image
    tv = v - 9 if v - 9 - th > 0 else v + 9 + th
    cv2.putText(img, "entrance", (tu, tv), FONT, scale, (0, 0, 0), 3, cv2.LINE_AA)
    cv2.putText(img, "entrance", (tu, tv), FONT, scale, (40, 200, 40), 1, cv2.LINE_AA)
    return img

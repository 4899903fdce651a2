#!/usr/bin/env python3
"""Writes the malformed-input corpus in tests/cases/bad/ from a small valid case (good.json, the
example case with every 8th contour point), and expected.tsv: file, command, and a substring the
error message must contain. Run from tests/cases/: python3 make_bad.py"""
import copy, json, os

base = json.load(open("../../examples/case/case.json"))
for v in base["views"]:
    v.pop("image", None)
    for c in v["contours"]:
        c["points"] = c["points"][::8]
json.dump(base, open("good.json", "w"), indent=1)

out = "bad"
rows = []

def case(name, expect, mutate=None, text=None):
    path = os.path.join(out, name)
    if text is None:
        d = copy.deepcopy(base)
        mutate(d)
        text = json.dumps(d, indent=1)
    open(path, "w").write(text)
    rows.append((name, "reconstruct", expect))

good_text = json.dumps(base, indent=1)
case("truncated.json", "invalid JSON", text=good_text[: len(good_text) // 2])
case("empty.json", "invalid JSON", text="")
case("array.json", "invalid JSON", text="[]")
case("nan_literal.json", "invalid JSON", text=good_text.replace('"fx": ', '"fx": NaN, "x": ', 1))
case("infinite_number.json", "invalid JSON", text=good_text.replace('"cx": ', '"cx": 1e999, "x": ', 1))
def drop(path):
    def f(d):
        o = d
        for k in path[:-1]:
            o = o[k]
        del o[path[-1]]
    return f
def setv(path, val):
    def f(d):
        o = d
        for k in path[:-1]:
            o = o[k]
        o[path[-1]] = val
    return f
case("missing_views.json", "missing field `views`", drop(["views"]))
case("missing_template.json", "missing field `template`", drop(["template"]))
case("missing_k.json", "views[0].k.fx", drop(["views", 0, "k"]))
case("missing_fy.json", "views[1].k.fy", drop(["views", 1, "k", "fy"]))
case("missing_height.json", "views[0].width/height = width 2048, height missing", drop(["views", 0, "height"]))
case("missing_size_without_image.json", "views[2].width/height", lambda d: (drop(["views", 2, "height"])(d), drop(["views", 2, "width"])(d)))
case("missing_closed.json", "closed/kind", drop(["views", 1, "contours", 0, "closed"]))
case("closed_and_kind_disagree.json", "closed/kind", setv(["views", 1, "contours", 0, "kind"], "open"))
case("unknown_contour_kind.json", "unknown variant `half`", setv(["views", 1, "contours", 0, "kind"], "half"))
case("extra_field.json", "unknown field `colour`", setv(["colour"], "red"))
case("extra_field_in_view.json", "unknown field `focal`", setv(["views", 0, "focal"], 1000))
case("wrong_type_fx.json", "field views[0].k.fx: invalid type", setv(["views", 0, "k", "fx"], "5500"))
case("wrong_type_points.json", "field views[0].contours[0].points: invalid type", setv(["views", 0, "contours", 0, "points"], "1,2;3,4"))
case("point_with_three_coordinates.json", "invalid JSON: field views[0].contours[0].points[0]", setv(["views", 0, "contours", 0, "points", 0], [1, 2, 3]))
case("negative_width.json", "invalid value", setv(["views", 0, "width"], -5))
case("huge_translation.json", "views[0].t[2]", setv(["views", 0, "t", 2], 1e300))
case("zero_focal_length.json", "views[0].k.fx", setv(["views", 0, "k", "fx"], 0))
case("negative_focal_length.json", "views[2].k.fy", setv(["views", 2, "k", "fy"], -5500))
case("non_orthonormal_rotation.json", "not orthonormal", lambda d: d["views"][1].__setitem__("r", [[1.1 * x for x in row] for row in d["views"][1]["r"]]))
case("reflecting_rotation.json", "reflection", lambda d: d["views"][0].__setitem__("r", [[-x for x in row] for row in d["views"][0]["r"]]))
case("model_behind_camera.json", "not in front of the source", setv(["views", 0, "t", 2], -5000))
case("source_inside_template.json", "reaches to or behind the source", setv(["views", 0, "t", 2], 20))
case("views_all_alike.json", "look along the same direction", lambda d: d.__setitem__("views", [copy.deepcopy(d["views"][0]) for _ in range(3)]))
case("contour_outside_image.json", "outside the 2048x2048 image", setv(["views", 1, "contours", 0, "points", 3], [90000, 90000]))
case("no_contours.json", "at least one contour", setv(["views", 2, "contours"], []))
case("one_point_contour.json", "at least 4 distinct points", setv(["views", 0, "contours", 0, "points"], [[1000, 1000]]))
case("empty_contour.json", "at least 4 distinct points", setv(["views", 0, "contours", 0, "points"], []))
case("duplicate_point_contour.json", "1 distinct points", setv(["views", 0, "contours", 0, "points"], [[1000, 1000]] * 20))
case("tiny_contour.json", "smaller than 2 pixels", setv(["views", 0, "contours", 0, "points"], [[1000, 1000], [1000.5, 1000], [1000.5, 1000.5], [1000, 1000.5]]))
case("stray_point.json", "points[5] = [1629.103746225825, 1515.888660477986]: a stray point", lambda d: d["views"][0]["contours"][0]["points"].__setitem__(5, [d["views"][0]["contours"][0]["points"][5][0] + 450, d["views"][0]["contours"][0]["points"][5][1] + 450]))
case("traced_twice.json", "views[0].contours[0].points = 40 points going 2 times round their centre", lambda d: d["views"][0]["contours"][0].__setitem__("points", d["views"][0]["contours"][0]["points"] * 2))
case("crossing_contour.json", "views[0].contours[0].points = 20 points enclosing", lambda d: d["views"][0]["contours"][0].__setitem__("points", d["views"][0]["contours"][0]["points"][:10] + d["views"][0]["contours"][0]["points"][10:][::-1]))
case("collinear_contour.json", "are its points on one line, or does it cross itself", setv(["views", 0, "contours", 0, "points"], [[900 + 10 * i, 800 + 5 * i] for i in range(20)]))
def second_closed(d):
    pts = d["views"][0]["contours"][0]["points"]
    d["views"][0]["contours"].append({"points": [[x + 150, y + 120] for x, y in pts], "closed": True})
case("two_closed_contours.json", "views[0].contours = 2 contours, 2 of them closed", second_closed)
case("closed_contour_and_arc.json", "views[1].contours = 2 contours, 1 of them closed", lambda d: d["views"][1]["contours"].append({"points": d["views"][1]["contours"][0]["points"][:8], "closed": False}))
def shrink(d):
    pts = d["views"][1]["contours"][0]["points"]
    cx = sum(x for x, y in pts) / len(pts); cy = sum(y for x, y in pts) / len(pts)
    d["views"][1]["contours"][0]["points"] = [[cx + 0.3 * (x - cx), cy + 0.3 * (y - cy)] for x, y in pts]
case("outline_at_another_scale.json", "mm at the object", shrink)
case("principal_point_at_origin.json", "views[1].contours = an outline whose centre's ray passes", lambda d: d["views"][1]["k"].update(cx=0, cy=0))
case("outline_shifted_off.json", "views[2].contours = an outline whose centre's ray passes", lambda d: d["views"][2]["contours"][0].__setitem__("points", [[p[0] + 400, p[1] - 300] for p in d["views"][2]["contours"][0]["points"]]))
case("one_view.json", "at least 2 views", lambda d: d.__setitem__("views", d["views"][:1]))
case("too_many_views.json", "at most 64 views", lambda d: d.__setitem__("views", d["views"] * 22))
case("zero_width.json", "image size", setv(["views", 0, "width"], 0))
case("absurd_image_size.json", "image size", setv(["views", 1, "height"], 10**6))
case("zero_radius.json", "template.radius", setv(["template", "radius"], 0))
case("absurd_radius.json", "template.radius", setv(["template", "radius"], 1e6))
case("zero_axis.json", "template.axis", setv(["template", "axis"], [0, 0, 0]))
case("huge_template_centre.json", "template.center[0]", setv(["template", "center", 0], 1e12))
case("missing_image.json", "image file not found", setv(["views", 0, "image"], "no_such_image.png"))
case("unreadable_image.json", "cannot be decoded", setv(["views", 0, "image"], "not_an_image.png"))
case("image_size_mismatch.json", "the view says", setv(["views", 0, "image"], "small.png"))
open(os.path.join(out, "not_an_image.png"), "w").write("this is not a PNG\n")
# An 8 x 8 grey PNG (valid, but not the view's size).
import zlib, struct
def png(w, h):
    raw = b"".join(b"\x00" + b"\x80" * w for _ in range(h))
    chunk = lambda t, d: struct.pack(">I", len(d)) + t + d + struct.pack(">I", zlib.crc32(t + d) & 0xFFFFFFFF)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 0, 0, 0, 0)) + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b"")
open(os.path.join(out, "small.png"), "wb").write(png(8, 8))
# Meshes for `acetab simulate --gt`.
open(os.path.join(out, "empty.stl"), "wb").write(b"")
open(os.path.join(out, "degenerate.obj"), "w").write("v 0 0 0\nv 1 1 1\nv 2 2 2\nf 1 2 3\n")
open(os.path.join(out, "nan_vertex.obj"), "w").write("v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n")
open(os.path.join(out, "no_faces.obj"), "w").write("v 0 0 0\nv 1 0 0\nv 0 1 0\n")
open(os.path.join(out, "truncated.ply"), "w").write("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n")
open(os.path.join(out, "short_vertex_list.ply"), "w").write("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nend_header\n0 0 0\n1 0 0\n")
for name in ["empty.stl", "degenerate.obj", "nan_vertex.obj", "no_faces.obj", "truncated.ply"]:
    rows.append((name, "simulate", ""))
rows.append(("short_vertex_list.ply", "simulate", "not a valid PLY file"))
# Valid meshes no study can use: a flat grid (no sphere fits it) and a tetrahedron with corners
# 1e38 mm out (units?): refused up front by name, before any run.
grid = [f"v {i} {j} 0" for i in range(6) for j in range(6)]
grid += [f"f {i*6+j+1} {i*6+j+2} {i*6+j+8}\nf {i*6+j+1} {i*6+j+8} {i*6+j+7}" for i in range(5) for j in range(5)]
open(os.path.join(out, "flat_plane.obj"), "w").write("\n".join(grid) + "\n")
rows.append(("flat_plane.obj", "simulate", "ground truth sphere fit"))
open(os.path.join(out, "far_away.obj"), "w").write(
    "v 1e38 0 0\nv -1e38 0 0\nv 0 1e38 0\nv 0 0 1e38\nf 1 2 3\nf 1 3 4\nf 2 3 4\nf 1 2 4\n")
rows.append(("far_away.obj", "simulate", "is the mesh in millimetres?"))
# Two pieces in one file (two hips, a stray fragment): no sphere fits them, and the refusal names
# the pieces.
open(os.path.join(out, "two_pieces.obj"), "w").write(
    "v 0 0 0\nv 30 0 0\nv 0 30 0\nv 100 0 0\nv 130 0 0\nv 100 30 0\nf 1 2 3\nf 4 5 6\n")
rows.append(("two_pieces.obj", "simulate", "2 separate pieces"))
# A binary STL whose header counts one triangle fewer than it holds (a tetrahedron's four): read
# as it says, the last triangle would be dropped without a word.
tri = [((0, 0, 0), (30, 0, 0), (0, 30, 0)), ((0, 0, 0), (0, 30, 0), (0, 0, 30)),
       ((0, 0, 0), (0, 0, 30), (30, 0, 0)), ((30, 0, 0), (0, 0, 30), (0, 30, 0))]
stl = b"\0" * 80 + struct.pack("<I", len(tri) - 1)
for t in tri:
    stl += struct.pack("<3f", 0, 0, 0) + b"".join(struct.pack("<3f", *v) for v in t) + b"\0\0"
open(os.path.join(out, "undercounted.stl"), "wb").write(stl)
rows.append(("undercounted.stl", "simulate", "header says 3 triangles"))
with open(os.path.join(out, "expected.tsv"), "w") as f:
    f.write("# file\tcommand\texpected substring of the error\n")
    for r in rows:
        f.write("\t".join(r) + "\n")
print(len(rows), "cases")

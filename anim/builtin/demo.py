"""demo (7,330 triangles): the scene `make render` renders, shipped as files
inside the package (a bending tube of vertex keyframes, a bouncing, spinning
ball on TRS tracks, a textured floor, one point light), so that an installed
frustrace has it too. Written by assets/make_demo.py; unlike the generated
scenes it knows no exact motion."""
import shutil
from pathlib import Path

FILES = Path(__file__).resolve().parent / "demo"


class DemoScene:
    name = "demo"
    description = "bending tube (vertex keys), bouncing ball (TRS tracks), textured floor"
    target_triangles = 0
    path = FILES / "anim.yaml"

    @property
    def triangles(self):
        """Faces of each object's mesh (its first keyframe's), as the files write them."""
        import yaml
        objects = yaml.safe_load(self.path.read_text())["objects"]
        meshes = [o["mesh"] if "mesh" in o else o["keyframes"][0]["mesh"] for o in objects]
        return sum(line.startswith("f ") for m in meshes for line in (FILES / m).read_text().splitlines())

    def write(self, out_dir):
        """Copy anim.yaml and its files into out_dir; returns the anim.yaml path."""
        out_dir = Path(out_dir)
        out_dir.mkdir(parents=True, exist_ok=True)
        for f in FILES.iterdir():
            if f.is_file():
                shutil.copy(f, out_dir / f.name)
        return out_dir / "anim.yaml"

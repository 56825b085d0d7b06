#pragma once
// Shared by the pipeline tests: a synthetic video written as PNG folders, a fake SfM back end that
// returns its exact cameras, and small reconstruction options.
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include <unistd.h>

#include "video3dgs/io/image_io.hpp"
#include "video3dgs/pipeline/reconstruct.hpp"
#include "video3dgs/synthetic/clip.hpp"

namespace test_pipeline {

using namespace video3dgs;
namespace fs = std::filesystem;

inline fs::path temp_dir(const std::string& name) {
  const auto d = fs::temp_directory_path() / ("video3dgs_pipe_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(d);
  fs::create_directories(d);
  return d;
}

struct Video {
  synthetic::SyntheticClip<float> clip;
  fs::path dir;
};

inline Video write_video(const fs::path& dir, int frames = 10) {
  synthetic::SyntheticClipOptions so;
  so.frames = frames;
  so.width = 48;
  so.height = 36;
  so.object_gaussians = 400;
  so.background_gaussians = 800;
  so.foreground_points = 120;
  Video v{synthetic::make_synthetic_clip<float>(so), dir};
  fs::create_directories(dir / "frames");
  fs::create_directories(dir / "masks");
  for (int f = 0; f < frames; ++f) {
    char name[32];
    std::snprintf(name, sizeof(name), "%05d.png", f);
    io::write_png(dir / "frames" / name, v.clip.frames[std::size_t(f)]);
    io::write_png(dir / "masks" / name, v.clip.masks[std::size_t(f)]);
  }
  return v;
}

/// Exact cameras of the frames asked for (all frames share the t = 0 points).
struct FakeSfm {
  const synthetic::SyntheticClip<float>* clip;
  int calls = 0;
  SfmResult<double> operator()(FrameRange r) {
    ++calls;
    SfmResult<double> s;
    s.status = SfmStatus::success;
    s.range = r;
    for (int f = r.first; f <= r.last; ++f) {
      s.frames.push_back(f);
      s.cameras.push_back(clip->cameras[std::size_t(f)].cast<double>());
    }
    s.points = clip->points;
    return s;
  }
};

inline pipeline::ReconstructOptions options(const Video& v, const fs::path& out) {
  pipeline::ReconstructOptions o;
  o.frames_dir = v.dir / "frames";
  o.masks_dir = v.dir / "masks";
  o.out = out;
  o.iterations = 100;
  o.k = 6;
  o.model.background.points_per_shell = 200;
  o.checkpoint_every = 0;
  return o;
}

/// `options` for one clip of a 6-frame video (k = 6), 24 iterations: the stop / resume cases.
inline pipeline::ReconstructOptions one_clip_options(const Video& v, const fs::path& out) {
  auto o = options(v, out);
  o.k = 6;
  o.iterations = 24;
  return o;
}

inline std::string slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

}  // namespace test_pipeline

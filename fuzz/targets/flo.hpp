#pragma once
// Fuzz target `flo`: flow::decode_flo. Seeds: small flow fields (one with "unknown" pixels) written by
// flow::encode_flo.
#include <filesystem>
#include <limits>
#include <string>
#include <string_view>

#include "../common.hpp"
#include "video3dgs/flow/flo_io.hpp"

namespace video3dgs::fuzz {

inline std::string flo(std::string_view bytes) {
  return run_reader([&] { (void)flow::decode_flo(bytes, "fuzz.flo"); });
}

inline void flo_seeds(const std::filesystem::path& dir) {
  for (const auto& [w, h] : {std::pair{1, 1}, std::pair{3, 2}, std::pair{4, 5}}) {
    flow::FlowFieldF f(w, h);
    for (std::size_t i = 0; i < f.size(); ++i) f.data()[i] = 0.5f * float(i) - 1.0f;
    if (w == 4) f.data()[3] = std::numeric_limits<float>::quiet_NaN();
    write_seed(dir, "flow_" + std::to_string(w) + "x" + std::to_string(h) + ".flo", flow::encode_flo<float>(f.view()));
  }
}

}  // namespace video3dgs::fuzz

// How much of a picture a mesh covers: shared by the render tests and the viewer's end-to-end
// tests.
#pragma once

#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <glm/vec3.hpp>

#include "client/render/image.h"

namespace isostream::testing {

// Fraction of pixels that differ from `background` (0..1 per channel) by more than a rounding
// step in some channel.
inline double Coverage(const render::Image& image, const glm::vec3& background) {
  size_t covered = 0;
  for (int y = 0; y < image.height; ++y)
    for (int x = 0; x < image.width; ++x) {
      const uint8_t* p = image.pixel(x, y);
      for (int c = 0; c < 3; ++c)
        if (std::abs(int(p[c]) - int(std::lround(background[c] * 255.0f))) > 2) {
          ++covered;
          break;
        }
    }
  return double(covered) / (double(image.width) * image.height);
}

}  // namespace isostream::testing

// Notes the CLI and the viewer print beside a frame whose result would otherwise surprise a
// user: an isovalue outside the volume's values, a budget under the coarsest mesh, an empty
// mesh. One wording for every tool; each returns "" when there is nothing to say.
#pragma once

#include <cstdint>
#include <cstdio>
#include <string>

namespace isostream {

// "isovalue 5 lies outside VOLUME's values [0, 1]: no surface for it", and the like for an
// isovalue at the lowest value (a surface needs samples below it; at the highest it encloses
// the samples there).
// In single precision, as the extraction compares them (a float isovalue widened to double
// printed as 4.900000095367432).
std::string IsovalueOutsideNote(float iso, float min_value, float max_value,
                                const std::string& volume);

// "VOLUME's values [1e6, 1000000.0625] are 1 float step apart: ...", where the values span
// fewer than kCoarseValueSteps floats: data far from 0 (float64 measurements with a large
// offset, rounded to the single precision samples are held in) keep few distinct values, and
// an isovalue between two of them has no surface of its own.
inline constexpr int64_t kCoarseValueSteps = 4096;
std::string CoarseValuesNote(float min_value, float max_value, const std::string& volume);

// Prints "TOOL: note: ..." to stderr for each isovalue without a surface by the values alone,
// outside (min_value, max_value] (and CoarseValuesNote's, if any), and returns whether some
// isovalue lies within (FrameNote's some_isovalue_inside).
template <typename Isovalues>
bool NoteIsovaluesOutside(const char* tool, const Isovalues& isovalues, float min_value,
                          float max_value, const std::string& volume) {
  const std::string coarse = CoarseValuesNote(min_value, max_value, volume);
  if (!coarse.empty()) std::fprintf(stderr, "%s: note: %s\n", tool, coarse.c_str());
  bool some_inside = false;
  for (const float iso : isovalues) {
    const std::string note = IsovalueOutsideNote(iso, min_value, max_value, volume);
    if (!note.empty()) std::fprintf(stderr, "%s: note: %s\n", tool, note.c_str());
    some_inside |= note.empty();
  }
  return some_inside;
}

// For a frame of `triangles` at `eps_used`, asked for with `budget` (0: none) and fitted to
// `fitted` (a daemon's FrameStats::triangle_budget, lower where its frame limit lowered the
// budget; `budget` otherwise), where `some_isovalue_inside`: some isovalue lies in the
// volume's (min, max] (else the notes of IsovalueOutsideNote have said why the mesh is empty).
std::string FrameNote(int64_t triangles, int64_t budget, int64_t fitted, double eps_used,
                      bool some_isovalue_inside);

}  // namespace isostream

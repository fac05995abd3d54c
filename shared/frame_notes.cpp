#include "shared/frame_notes.h"

#include <cstring>

#include "shared/number_list.h"

namespace isostream {

std::string IsovalueOutsideNote(float iso, float min_value, float max_value,
                                const std::string& volume) {
  // A surface bounds the samples >= iso against those below it: none lies below the lowest.
  if (iso == min_value)
    return "isovalue " + ShortestText(iso) + " is " + volume +
           "'s lowest value: no sample lies below it, so no surface bounds it";
  if (iso > min_value && iso <= max_value) return "";
  return "isovalue " + ShortestText(iso) + " lies outside " + volume + "'s values [" +
         ShortestText(min_value) + ", " + ShortestText(max_value) + "]: no surface for it";
}

std::string CoarseValuesNote(float min_value, float max_value, const std::string& volume) {
  // Floats in order as integers: the count of floats between two values.
  const auto order = [](float f) {
    int32_t bits;
    std::memcpy(&bits, &f, sizeof bits);
    return bits < 0 ? -int64_t(bits & 0x7fffffff) : int64_t(bits);
  };
  if (!(min_value < max_value)) return "";
  const int64_t steps = order(max_value) - order(min_value);
  if (steps >= kCoarseValueSteps) return "";
  return volume + "'s values [" + ShortestText(min_value) + ", " + ShortestText(max_value) +
         "] are " + std::to_string(steps) + " float step" + (steps == 1 ? "" : "s") +
         " apart: far from 0, single precision keeps few values (surfaces step between them); "
         "subtract an offset such as " +
         ShortestText(min_value) + " before storing";
}

std::string FrameNote(int64_t triangles, int64_t budget, int64_t fitted, double eps_used,
                      bool some_isovalue_inside) {
  // The budget search answers with the coarsest mesh when even that is over the budget.
  if (budget > 0 && triangles > budget)
    return "the coarsest mesh (eps " + ShortestText(eps_used) + ") has " +
           std::to_string(triangles) + " triangles, over the budget of " + std::to_string(budget) +
           ": no coarser mesh exists";
  // The daemon's frame limit lowered the budget, and that made the mesh coarser: the user's
  // budget alone would not explain the eps.
  if (budget > 0 && fitted > 0 && fitted < budget && eps_used > 0)
    return "the budget of " + std::to_string(budget) +
           " triangles is over the daemon's frame limit: the frame was fitted to its limit of " +
           std::to_string(fitted) + " (isostreamd --max-triangles)";
  // Only an eps above 0 can be lowered. A budget's search stops at an empty mesh above 0 when
  // the next finer mesh is over the budget (a budget of 1, say): the budget is what to change.
  if (triangles == 0 && eps_used > 0 && some_isovalue_inside && budget > 0)
    return "the mesh is empty at eps " + ShortestText(eps_used) +
           ": the next finer mesh is over the budget of " + std::to_string(budget) +
           " triangles; a larger budget draws the surfaces";
  if (triangles == 0 && eps_used > 0 && some_isovalue_inside)
    return "the mesh is empty at eps " + ShortestText(eps_used) +
           ": a smaller eps (data units) refines the coarse tetrahedra that miss the surfaces";
  return "";
}

}  // namespace isostream

// eta for a hierarchy whose samples store stand-ins for the planes deep in the padding
// (stored_planes.h). Private to server/hierarchy: BuildHierarchy calls it.
#pragma once

#include "server/hierarchy/hierarchy.h"
#include "server/volume/padded_samples.h"

namespace isostream {

// Fills h's store (set up by SetUpStore for these samples) with the samples and their eta,
// using the samples' array as scratch. False if a sample is not finite. Stops early, leaving
// the store unfinished, once options.stop is set.
bool BuildWithStandIns(PaddedSamples* samples, Hierarchy* h, const HierarchyBuildOptions& options);

}  // namespace isostream

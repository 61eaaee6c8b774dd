// The 8-connected moves of the grid searches (GridPlanner, LandmarkBounds' whole-map searches):
// moves 0-3 straight (+x, -x, +y, -y), 4-7 diagonal; a diagonal move needs both straight moves
// beside it open (no squeezing between two blocked cells): kSideX / kSideY name them.
#pragma once

namespace tessera::navigation::moves {

inline constexpr int kDx[8] = {1, -1, 0, 0, 1, 1, -1, -1};
inline constexpr int kDy[8] = {0, 0, 1, -1, 1, -1, 1, -1};
inline constexpr int kSideX[8] = {0, 0, 0, 0, 0, 0, 1, 1};
inline constexpr int kSideY[8] = {0, 0, 0, 0, 2, 3, 2, 3};

}  // namespace tessera::navigation::moves

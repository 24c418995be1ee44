"""fitting: batched, differentiable parameter fits built on pmpjax (never imported by pmpjax)."""
